#!/usr/bin/env bash
# Ablation of the modalities (`make bench`, or bench/ablation.sh BUILD_DIR [SCENARIO...]): each
# shipped scenario is simulated once (cameras left out: nothing fuses them yet), then replayed
# through `hanzo-fusion run` with the IMU plus each single modality, with every sensor, and without
# the IMU (the LiDAR alone, every other sensor); the
# table gives the APE RMSE of the real-time and the optimized trajectory, in the world frame (no
# alignment: meaningful where GNSS fixes the frame), yaw-aligned (the error in a level world: the
# IMU measures gravity) and SE3-aligned (the shape alone), the real-time poses' world-frame APE
# once tracking (evaluation_tracking: without those before GNSS gave the heading), and the
# run's speed. The outputs stay in BUILD_DIR/ablation/.
set -euo pipefail
build_dir=${1:-build}
shift || true
cd "$(dirname "$0")/.."
cli="$build_dir/apps/hanzo-fusion"
scenarios=("$@")
[ ${#scenarios[@]} -gt 0 ] || scenarios=(urban_vehicle warehouse_robot gnss_outage_vehicle delivery_van)
work="$build_dir/ablation"
mkdir -p "$work"

printf "%-20s %-28s %13s %13s %13s %13s %13s %13s %13s %8s\n" scenario sensors "APE real-time" "APE optimized" "yaw real-time" "yaw optimized" \
  "SE3 real-time" "SE3 optimized" "APE tracking" "x rt"
for scenario in "${scenarios[@]}"; do
  sim="$work/$scenario"
  if [ ! -f "$sim/sensors.mcap" ]; then
    sensors=$(/usr/bin/python3 -c "
import re, sys
names, block = [], False
for line in open('examples/scenarios/$scenario.yaml'):
    if re.match(r'^  sensors:', line): block = True; continue
    if block and re.match(r'^  \S', line): break
    m = re.match(r'^    ([A-Za-z0-9_]+):', line)
    if block and m and not m.group(1).startswith('camera'): names.append(m.group(1))
print(','.join(names))")
    "$cli" sim "examples/scenarios/$scenario.yaml" --out "$sim" --sensors "$sensors" --threads 0 --no-foxglove > /dev/null
  fi
  configured=$(/usr/bin/python3 -c "
import re
names, block = [], False
for line in open('$sim/fusion.yaml'):
    if re.match(r'^  sensors:', line): block = True; continue
    m = re.match(r'^    ([A-Za-z0-9_]+):', line)
    if block and m: names.append(m.group(1))
print(' '.join(names))")
  imu=$(for name in $configured; do case $name in imu*) echo "$name"; break;; esac; done)
  subsets=()
  for name in $configured; do [ "$name" = "$imu" ] || subsets+=("$imu,$name"); done
  subsets+=("$(echo $configured | tr ' ' ',')")
  # Without the IMU (the Frontend's motion model): the LiDAR alone and every other sensor.
  without_imu=$(for name in $configured; do [ "$name" = "$imu" ] || echo "$name"; done | paste -sd, -)
  for name in $configured; do case $name in lidar*) [ "$name" = "$without_imu" ] || subsets+=("$name");; esac; done
  subsets+=("$without_imu")
  for subset in "${subsets[@]}"; do
    out="$work/$scenario-run-${subset//,/+}"
    "$cli" run --config "$sim/fusion.yaml" --calib "$sim/calibration.yaml" --log "$sim/sensors.mcap" --out "$out" \
      --gt "$sim/ground_truth.tum" --sensors "$subset" --threads 0 --json > "$out.json" 2> /dev/null || true
    /usr/bin/python3 - "$scenario" "$subset" "$out.json" <<'PY'
import json, sys
scenario, subset, path = sys.argv[1:4]
try:
    result = json.load(open(path))
except ValueError:
    print(f"{scenario:<20} {subset:<28} {'failed':>12}")
    sys.exit(0)
def ape(key, metric):
    value = result.get(key, {}).get(metric)
    return f"{value:.3f} m" if isinstance(value, float) else "undefined"
columns = [ape(key, metric) for metric in ("ape_rmse_m", "ape_yaw_aligned_rmse_m", "ape_se3_aligned_rmse_m")
           for key in ("evaluation", "evaluation_optimized")] + [ape("evaluation_tracking", "ape_rmse_m")]
print(f"{scenario:<20} {subset:<28} " + " ".join(f"{c:>13}" for c in columns) + f" {result['timing']['realtime_factor']:>8.1f}")
PY
  done
done
