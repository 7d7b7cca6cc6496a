#!/usr/bin/env bash
# Interleaved A/B of one benchmark between a commit and the current build, for machines whose
# timings drift by tens of percent within minutes (compare runs of the same sitting only).
# Builds REF in a git worktree under build-ab/ (ignored; ccache keeps rebuilds short), then runs
# the benchmark from both builds ROUNDS times, alternating base and work, and prints each run's
# real time and its counters whose names end in _ms.
#
# usage: scripts/bench-ab.sh REF BENCHMARK [FILTER] [ROUNDS]
#   scripts/bench-ab.sh HEAD~1 bench_lidar 'hanzo/gicp/voxel:0.25' 3
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: scripts/bench-ab.sh REF BENCHMARK [FILTER] [ROUNDS]" >&2
  exit 2
fi
ref=$1 benchmark=$2 filter=${3:-.} rounds=${4:-2}
cd "$(dirname "$0")/.."
root=$(pwd)
commit=$(git rev-parse --verify "$ref^{commit}")
source_dir=$root/build-ab/source
mkdir -p "$root/build-ab"
if [ -d "$source_dir" ]; then
  git -C "$source_dir" checkout -q --detach "$commit"
else
  git worktree add -q --detach "$source_dir" "$commit"
fi
# The configure step wants the web viewer's npm packages; the base uses the current ones.
[ -e "$source_dir/web/node_modules" ] || ln -s "$root/web/node_modules" "$source_dir/web/node_modules"
cmake -S "$source_dir" -B "$root/build-ab/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DPython_EXECUTABLE=/usr/bin/python3 > "$root/build-ab/configure.log" 2>&1 ||
  { echo "bench-ab: configuring $ref failed (build-ab/configure.log)" >&2; exit 1; }
ninja -C "$root/build-ab/build" "bench/$benchmark" > "$root/build-ab/build.log" 2>&1 ||
  { echo "bench-ab: building $benchmark at $ref failed (build-ab/build.log)" >&2; exit 1; }
ninja -C build "bench/$benchmark" > /dev/null ||
  { echo "bench-ab: building $benchmark in build/ failed" >&2; exit 1; }
echo "base = $ref (${commit:0:10}), work = build/ ($(git rev-parse --short HEAD) + working tree)"
for round in $(seq "$rounds"); do
  for side in base work; do
    binary=build/bench/$benchmark
    [ "$side" = base ] && binary=build-ab/build/bench/$benchmark
    "$binary" --benchmark_filter="$filter" --benchmark_format=json 2>/dev/null | /usr/bin/python3 -c '
import json, sys
for run in json.load(sys.stdin)["benchmarks"]:
    if run.get("run_type") != "iteration":
        continue
    name, time, unit = run["run_name"], run["real_time"], run["time_unit"]
    stages = " ".join(f"{key} {value:.2f}" for key, value in run.items() if key.endswith("_ms"))
    print(f"{sys.argv[1]} {sys.argv[2]} {name}: {time:.3f} {unit} {stages}")
' "$side" "$round"
  done
done
