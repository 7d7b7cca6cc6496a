#!/usr/bin/env bash
# Trains the learned place-recognition model (models/trained/vlad_aliked-t16.hzvlad): the cluster
# centres and whitened projection of VLAD over ALIKED-T16 descriptors (vision/vlad.hpp), on the
# simulator's camera images of a city the evaluation route does not drive (city seed 12; the
# evaluation's city_loop_day / city_loop_dusk scenarios use seed 11), once each in the midday
# sun, at dusk and overcast with snow. About 4 minutes on 2 cores.
#   usage: train.sh HANZO_FUSION_CLI WORK_DIR OUT_MODEL
# The ALIKED weights are found in $HANZO_FUSION_MODELS (default ../shared/models).
set -euo pipefail
cli=$1 work=$2 out=$3
here=$(cd "$(dirname "$0")" && pwd)
export HANZO_FUSION_MODELS=${HANZO_FUSION_MODELS:-$here/../../../../shared/models}
mkdir -p "$work"
logs=()
for lighting in day dusk overcast; do
  rm -rf "$work/$lighting"
  "$cli" sim "$here/training_city_$lighting.yaml" --out "$work/$lighting" --threads 0 > /dev/null
  logs+=("$work/$lighting/sensors.mcap")
done
"$cli" vision vlad "${logs[@]}" --detector aliked-t16 --every 4 --clusters 32 --dimensions 128 --out "$out"
