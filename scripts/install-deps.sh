#!/usr/bin/env bash
# Installs the Debian 12 packages hanzo-fusion builds against. Idempotent: when every package
# is already installed it runs one dpkg query per package and exits (well under a second).
# Needs root (or sudo) only when something is missing.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git
  # core: linear algebra, geodesy, YAML, logging, JSON output
  libeigen3-dev libgeographiclib-dev libyaml-cpp-dev libspdlog-dev libfmt-dev nlohmann-json3-dev
  # msgs: protobuf schemas and the gRPC service
  libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  # apps
  libcli11-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null | grep -qx installed || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root to install: ${missing[*]}" >&2; exit 1; }
  sudo_cmd=(sudo)
fi
echo "install-deps: installing ${missing[*]}"
"${sudo_cmd[@]}" apt-get update -qq
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
