#!/usr/bin/env python3
"""The replica deployment of docs/server.md end to end: scripts/replicas.sh starts PostgreSQL,
s3rver, 3 replicas and nginx; a simulated warehouse drive streams through nginx (REST creates
the session, gRPC carries IMU + LiDAR); the replica serving it is killed (kill -9); after the
lease the session answers through nginx from another replica with every pose stored before the
kill, and a second stream goes on into it there.

usage: replicas_deployment_test.py --cli build/apps/hanzo-fusion
"""
import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
LEASE_S = 2.0


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def request(method, url, body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as answer:
            return answer.status, json.loads(answer.read() or b"null")
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read() or b"null")


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--cli", required=True)
    args = parser.parse_args()
    cli = str(Path(args.cli).resolve())
    work = Path(tempfile.mkdtemp(prefix="hanzo_replicas_"))
    work.chmod(0o755)  # as root, PostgreSQL runs as the postgres user and must reach its folder
    drive = work / "drive"
    subprocess.run([cli, "sim", "examples/scenarios/warehouse_robot.yaml", "--out", str(drive), "--duration", "12"], check=True,
                   cwd=REPO, stdout=subprocess.DEVNULL)
    rest_port, grpc_port = free_port(), free_port()
    deployment = work / "deployment"
    environment = dict(os.environ, HANZO_FUSION=cli, HANZO_FUSION_LEASE_S=str(LEASE_S))
    environment.pop("HANZO_FUSION_TOKENS_FILE", None)
    subprocess.run(["bash", str(REPO / "scripts" / "replicas.sh"), "start", str(deployment), "3", str(rest_port), str(grpc_port)],
                   check=True, env=environment)
    try:
        endpoints = json.loads((deployment / "endpoints.json").read_text())
        rest = endpoints["rest_url"]
        assert len(endpoints["replicas"]) == 3
        pids = {replica["id"]: replica["pid"] for replica in endpoints["replicas"]}

        # Stream the drive through nginx; the session ends up on the replica its id hashes to.
        streamed = subprocess.run([cli, "stream", str(drive / "sensors.mcap"), "--server", f"127.0.0.1:{grpc_port}", "--rest", rest,
                                   "--config", str(drive / "fusion.yaml"), "--calib", str(drive / "calibration.yaml"), "--rate", "max",
                                   "--json"], cwd=REPO, capture_output=True, text=True, timeout=600)
        if streamed.returncode != 0:
            fail(f"stream through nginx: {streamed.stderr}")
        session_id = json.loads(streamed.stdout)["session_id"]
        status, session = request("GET", f"{rest}/v1/sessions/{session_id}")
        if status != 200 or session["replica"] not in pids:
            fail(f"session through nginx: {status} {session}")
        serving = session["replica"]
        if session["mapping"]["scans_registered"] < 60:
            fail(f"the session mapped {session['mapping']['scans_registered']} sweeps")
        status, listed = request("GET", f"{rest}/v1/sessions")
        if status != 200 or [s["replica"] for s in listed["sessions"]] != [serving]:
            fail(f"listed through nginx: {status} {listed}")
        time.sleep(0.5)  # the poses queued are committed every 20 ms
        status, page = request("GET", f"{rest}/v1/sessions/{session_id}/trajectory?limit=100000")
        stored_before = len(page["poses"])
        if status != 200 or stored_before < 1000:
            fail(f"trajectory through nginx: {status}, {stored_before} poses")

        os.kill(pids[serving], signal.SIGKILL)
        killed_at = time.monotonic()
        taken_over = None
        while time.monotonic() - killed_at < LEASE_S + 20:
            status, session = request("GET", f"{rest}/v1/sessions/{session_id}")
            if status == 200 and session["replica"] not in (None, serving):
                taken_over = session["replica"]
                break
            time.sleep(0.2)
        if taken_over is None:
            fail(f"nobody took the session over: {status} {session}")
        waited = time.monotonic() - killed_at
        status, page = request("GET", f"{rest}/v1/sessions/{session_id}/trajectory?limit=100000")
        if status != 200 or len(page["poses"]) < stored_before:
            fail(f"poses stored before the kill were lost: {len(page['poses'])} < {stored_before}")

        # A stream into the same session through nginx reaches its new replica (the log's times
        # are older than the session's: what it takes or refuses is not checked here).
        again = subprocess.run([cli, "stream", str(drive / "sensors.mcap"), "--server", f"127.0.0.1:{grpc_port}", "--rest", rest,
                                "--session", session_id, "--rate", "max", "--json"], cwd=REPO, capture_output=True, text=True, timeout=600)
        if again.returncode != 0:
            fail(f"streaming into the taken-over session: {again.stderr}")
        status, session = request("GET", f"{rest}/v1/sessions/{session_id}")
        if status != 200 or session["replica"] in (None, serving):
            fail(f"after the second stream: {status}, replica {session.get('replica')}")
        print(json.dumps({"serving": serving, "taken_over_by": taken_over, "after_second_stream": session["replica"],
                          "answered_after_kill_s": round(waited, 2), "stored_before_kill": stored_before, "stored_now": session["stored_poses"]}))
    finally:
        subprocess.run(["bash", str(REPO / "scripts" / "replicas.sh"), "stop", str(deployment)], env=environment)


if __name__ == "__main__":
    main()
