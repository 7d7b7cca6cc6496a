#!/usr/bin/env bash
# `make container`: builds the server image from Dockerfile with Debian's podman and checks that
# a running container answers REST (/v1/health, a session created and streamed into) and gRPC
# (`hanzo-fusion stream` of the sample log) and that its health check passes.
# Without a registry the base is a Debian 12 root made here by debootstrap (localhost/debian:bookworm).
# usage: scripts/container.sh BUILD_DIR   (BUILD_DIR: a build of the project, for its client)
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
image=localhost/hanzo-fusion:latest
base=localhost/debian:bookworm
need=()
for tool in podman runc debootstrap curl; do command -v "$tool" > /dev/null || need+=("$tool"); done
if [ ${#need[@]} -gt 0 ]; then
  apt-get update > /dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y podman runc debootstrap curl > /dev/null
fi
# crun (podman's default runtime) cannot set the rlimits or use the hybrid cgroups of some
# sandboxed machines; runc with cgroupfs and rlimits within the current ones runs everywhere.
flags=(--runtime runc --cgroup-manager=cgroupfs)
limits=(--ulimit nofile=1024:1024 --ulimit nproc=4096:4096)
if ! podman image exists "$base"; then
  root=$(mktemp -d)
  debootstrap --variant=minbase bookworm "$root" http://deb.debian.org/debian > /dev/null
  tar -C "$root" -c . | podman import - "$base" > /dev/null
  rm -rf "$root"
fi
bash scripts/install-deps.sh  # web/node_modules, which the image's build bundles the viewer with
# The docker format keeps the image's HEALTHCHECK (OCI images have none).
podman "${flags[@]}" build "${limits[@]}" --format docker --build-arg BASE="$base" -t "$image" .

# The server refuses to start without authentication: a token for the check.
token=container-check-$(od -An -N8 -tx1 /dev/urandom | tr -d ' \n')
name=hanzo-fusion-check-$$
trap 'podman "${flags[@]}" rm -f "$name" > /dev/null 2>&1 || true' EXIT
podman "${flags[@]}" run -d --name "$name" "${limits[@]}" -e HANZO_FUSION_TOKENS="$token=check:fusion:admin" -p 18083:8083 -p 18084:8084 "$image" > /dev/null
for _ in $(seq 1 50); do curl -fsS http://127.0.0.1:18083/v1/health > /dev/null 2>&1 && break; sleep 0.2; done
echo "REST: $(curl -fsS http://127.0.0.1:18083/v1/health)"
echo "user: $(podman "${flags[@]}" exec "$name" id -un)"
podman "${flags[@]}" healthcheck run "$name" && echo "health check: healthy"
log=$(mktemp -d)/sample.mcap
"$build_dir/apps/hanzo-fusion" import csv examples/data/imu.csv examples/data/gnss.csv examples/data/wheels.csv --out "$log" > /dev/null
"$build_dir/apps/hanzo-fusion" stream "$log" --server 127.0.0.1:18084 --rest http://127.0.0.1:18083 \
  --config examples/data/fusion.yaml --calib examples/data/calibration.yaml --rate max --end --token "$token"
echo "gRPC: the sample log streamed into a session of the container"
