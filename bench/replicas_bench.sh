#!/usr/bin/env bash
# Replicas under load (docs/server.md "Replicas"): the simulated warehouse drive (IMU 200 Hz +
# VLP-16 at 10 Hz) streamed in real time into sessions behind nginx (scripts/replicas.sh:
# PostgreSQL, s3rver, nginx), 3 replicas with 30 sessions against 1 replica with 10 (the same
# load per process), each through bench_server_load --endpoint. Everything shares this machine.
#
#   bash bench/replicas_bench.sh [BUILD_DIR] [SECONDS]     (defaults: build, 60)
set -euo pipefail
build_dir="$(cd "${1:-build}" && pwd)"
seconds="${2:-60}"
cd "$(dirname "$0")/.."
free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
for setup in "1 10" "3 30"; do
  read -r replicas sessions <<<"$setup"
  dir="$(mktemp -d /tmp/hanzo_replicas_bench_XXXXXX)"
  rest_port="$(free_port)"
  grpc_port="$(free_port)"
  HANZO_FUSION="$build_dir/apps/hanzo-fusion" bash scripts/replicas.sh start "$dir" "$replicas" "$rest_port" "$grpc_port" >&2
  pids="$(/usr/bin/python3 -c 'import json, sys; print(",".join(str(r["pid"]) for r in json.load(open(sys.argv[1]))["replicas"]))' "$dir/endpoints.json")"
  echo "== $replicas replica(s), $sessions sessions, $seconds s"
  status=0
  "$build_dir/bench/bench_server_load" --sessions "$sessions" --seconds "$seconds" --stagger \
    --endpoint "http://127.0.0.1:$rest_port,127.0.0.1:$grpc_port" --server-pids "$pids" || status=$?
  bash scripts/replicas.sh stop "$dir"
  rm -rf "$dir"
  [ "$status" -eq 0 ] || { echo "replicas_bench: messages were lost ($replicas replicas, $sessions sessions)" >&2; exit "$status"; }
done
