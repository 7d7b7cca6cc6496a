#!/usr/bin/env bash
# `make demo`: the main job on the sample data shipped in examples/. For now this validates
# the shipped fusion configuration and calibration and prints their summaries; later issues
# make it replay a sample sensor log through the engine.
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
cli="$build_dir/apps/hanzo-fusion"

echo "== hanzo-fusion config check examples/fusion.yaml"
"$cli" config check examples/fusion.yaml
echo
echo "== hanzo-fusion calib check examples/calibration.yaml"
"$cli" calib check examples/calibration.yaml
