#!/usr/bin/env bash
# `make fuzz`: builds the fuzz targets (fuzz/) with clang's libFuzzer and AddressSanitizer in
# BUILD_DIR (default build-fuzz) and runs each for FUZZ_SECONDS (default 60), or until FUZZ_RUNS
# executions (default: no limit), from its seed corpus (fuzz/corpus/NAME; new inputs that reach new code are kept in BUILD_DIR/corpus/NAME).
# A crash stops the run and leaves the input as crash-* in the current folder:
# rerun it with BUILD_DIR/fuzz/fuzz_NAME crash-... (the GCC build's ctest runs the same targets
# briefly, through fuzz/standalone_driver.cpp).
set -euo pipefail
BUILD_DIR=${1:-build-fuzz}
FUZZ_SECONDS=${FUZZ_SECONDS:-60}
FUZZ_RUNS=${FUZZ_RUNS:--1}
command -v clang++ > /dev/null || { echo "make fuzz: clang++ is missing (scripts/install-deps.sh installs it)" >&2; exit 1; }
SANITIZE="-fsanitize=fuzzer-no-link,address"
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_C_FLAGS="$SANITIZE" -DCMAKE_CXX_FLAGS="$SANITIZE" -DHANZO_FUZZ_LIBFUZZER=ON -DHANZO_WERROR=OFF \
  -DHANZO_BUILD_APPS=OFF -DHANZO_BUILD_PYTHON=OFF -DHANZO_BUILD_BENCHMARKS=OFF -DPython_EXECUTABLE=/usr/bin/python3 > "$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log"; exit 1; }
targets=(json_requests proto_messages encrypted_files jwt_tokens ros_messages text_formats sensor_logs point_cloud_files s3_responses)
cmake --build "$BUILD_DIR" --target "${targets[@]/#/fuzz_}"
for target in "${targets[@]}"; do
  mkdir -p "$BUILD_DIR/corpus/$target"
  echo "== fuzz_$target for ${FUZZ_SECONDS} s"
  "$BUILD_DIR/fuzz/fuzz_$target" -max_total_time="$FUZZ_SECONDS" -runs="$FUZZ_RUNS" -print_final_stats=1 "$BUILD_DIR/corpus/$target" "fuzz/corpus/$target"
done
