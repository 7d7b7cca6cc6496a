#!/usr/bin/env bash
# `make bench`: runs every benchmark in bench/ and prints their tables.
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
for benchmark in "$build_dir"/bench/bench_*; do
  [ -x "$benchmark" ] || continue
  echo "== $(basename "$benchmark")"
  "$benchmark" --benchmark_counters_tabular=true
done
