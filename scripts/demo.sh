#!/usr/bin/env bash
# `make demo`: the main job on the sample data shipped in examples/: validate the fusion
# configuration and calibration, turn the sample CSV recordings into a sensor log (MCAP), list
# it, replay it through the pipeline (the Session: EKF and keyframe graph) and score it against its ground truth,
# simulate 8 s of the urban_vehicle scenario (all six sensors, with ground truth) and replay
# that too (LiDAR odometry, graph and map included), map its LiDAR sweeps with the true poses (FusionMap + PNG pictures), then score a
# sample estimate with evo's APE/RPE (SVG plots). Writes only into build/demo/.
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
cli="$build_dir/apps/hanzo-fusion"
out="$build_dir/demo"
mkdir -p "$out"

echo "== hanzo-fusion config check examples/fusion.yaml"
"$cli" config check examples/fusion.yaml
echo
echo "== hanzo-fusion calib check examples/calibration.yaml"
"$cli" calib check examples/calibration.yaml
echo
echo "== hanzo-fusion import csv examples/data/{imu,gnss,wheels}.csv --out $out/sample.mcap"
"$cli" import csv examples/data/imu.csv examples/data/gnss.csv examples/data/wheels.csv --out "$out/sample.mcap"
echo
echo "== hanzo-fusion log info $out/sample.mcap --verify"
"$cli" log info "$out/sample.mcap" --verify
echo
echo "== hanzo-fusion run --config examples/data/fusion.yaml --calib examples/data/calibration.yaml --log $out/sample.mcap --out $out/run --gt examples/data/ground_truth.tum"
"$cli" run --config examples/data/fusion.yaml --calib examples/data/calibration.yaml --log "$out/sample.mcap" --out "$out/run" --gt examples/data/ground_truth.tum
echo
echo "== hanzo-fusion sim examples/scenarios/urban_vehicle.yaml --out $out/urban --duration 8 --threads 0"
"$cli" sim examples/scenarios/urban_vehicle.yaml --out "$out/urban" --duration 8 --threads 0
echo
echo "== hanzo-fusion run --config $out/urban/fusion.yaml --calib $out/urban/calibration.yaml --log $out/urban/sensors.mcap --out $out/urban/run --gt $out/urban/ground_truth.tum"
"$cli" run --config "$out/urban/fusion.yaml" --calib "$out/urban/calibration.yaml" --log "$out/urban/sensors.mcap" \
  --out "$out/urban/run" --gt "$out/urban/ground_truth.tum"
echo
echo "== hanzo-fusion map build --log $out/urban/sensors.mcap --trajectory $out/urban/ground_truth.tum --calib $out/urban/calibration.yaml --topic /sensors/lidar --resolution 0.2 --height-band -1.5,1.5 --points-voxel 0.2 --out $out/urban/map.fmap"
"$cli" map build --log "$out/urban/sensors.mcap" --trajectory "$out/urban/ground_truth.tum" --calib "$out/urban/calibration.yaml" \
  --topic /sensors/lidar --resolution 0.2 --height-band -1.5,1.5 --points-voxel 0.2 --map-id urban-demo --out "$out/urban/map.fmap"
echo
echo "== hanzo-fusion map export $out/urban/map.fmap --out $out/urban/map.png (and --layer points --out $out/urban/map_points.png)"
"$cli" map export "$out/urban/map.fmap" --out "$out/urban/map.png"
"$cli" map export "$out/urban/map.fmap" --layer points --out "$out/urban/map_points.png"
echo
echo "== hanzo-fusion eval ape examples/data/ground_truth.tum examples/data/estimate.tum --align sim3 --plot $out"
"$cli" eval ape examples/data/ground_truth.tum examples/data/estimate.tum --align sim3 --plot "$out"
echo
echo "== hanzo-fusion eval rpe examples/data/ground_truth.tum examples/data/estimate.tum -d 1 -u m"
"$cli" eval rpe examples/data/ground_truth.tum examples/data/estimate.tum -d 1 -u m
