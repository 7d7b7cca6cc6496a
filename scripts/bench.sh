#!/usr/bin/env bash
# `make bench`: runs every benchmark in bench/ and prints their tables.
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
for benchmark in "$build_dir"/bench/bench_*; do
  [ -x "$benchmark" ] || continue
  echo "== $(basename "$benchmark")"
  case "$(basename "$benchmark")" in
    bench_server_load) "$benchmark" ;;  # its own table (not Google Benchmark): 20 sessions for 60 s
    bench_memory) "$benchmark" ;;       # its own table: a 10-minute flight, two configurations
    *) "$benchmark" --benchmark_counters_tabular=true ;;
  esac
done
echo "== ablation (bench/ablation.sh)"
bash bench/ablation.sh "$build_dir"
echo "== python layer (bench/python_bench.py)"
PYTHONPATH="$build_dir/python" /usr/bin/python3 bench/python_bench.py "$build_dir"
echo "== batch mapping on Dask (bench/batch_bench.py)"
PYTHONPATH="$build_dir/python" /usr/bin/python3 bench/batch_bench.py "$build_dir"
echo "== replicas behind nginx (bench/replicas_bench.sh)"
bash bench/replicas_bench.sh "$build_dir"
