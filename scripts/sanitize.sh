#!/usr/bin/env bash
# `make sanitize`: the test suite under AddressSanitizer + UndefinedBehaviorSanitizer (GCC, in
# BUILD_DIR-asan), then the service and pipeline tests under ThreadSanitizer (BUILD_DIR-tsan).
# Any report fails the run (halt_on_error). The Python and web-viewer tests are left out: they
# load the library into interpreters that are not built with the sanitizers; so is the install
# test, whose consumer project links the installed libraries without the sanitizer runtime.
# Under TSan the service tests that stream the urban recording's LiDAR sweeps take 30 minutes
# and more each (TBB loops run serially there): hence the 3-hour per-test limit.
# SANITIZE_TESTS (a ctest -R regex) narrows the ASan run, e.g. SANITIZE_TESTS='^(Mcap|Rosbag)'.
set -euo pipefail
build_dir=${1:-build}
cd "$(dirname "$0")/.."
jobs=$(nproc)
configure() {  # DIR FLAGS
  cmake -S . -B "$1" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_FLAGS="$2" -DCMAKE_CXX_FLAGS="$2" \
    -DCMAKE_EXE_LINKER_FLAGS="$2" -DCMAKE_SHARED_LINKER_FLAGS="$2" -DHANZO_BUILD_PYTHON=OFF -DHANZO_BUILD_BENCHMARKS=OFF \
    -DPython_EXECUTABLE=/usr/bin/python3 > "$1.configure.log" 2>&1 || { cat "$1.configure.log"; exit 1; }
}

asan="$build_dir-asan"
configure "$asan" "-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
cmake --build "$asan" -j "$jobs"
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export LSAN_OPTIONS=suppressions="$PWD/scripts/lsan.supp"
ctest --test-dir "$asan" --output-on-failure -j "$jobs" -E '^(python\.pytest|web\.viewer|install\..*)$' ${SANITIZE_TESTS:+-R "$SANITIZE_TESTS"}

tsan="$build_dir-tsan"
configure "$tsan" "-fsanitize=thread"
# Set before the build: gtest_discover_tests runs the test binaries.
export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1:suppressions="$PWD/scripts/tsan.supp"
cmake --build "$tsan" -j "$jobs" --target test_service test_pipeline hanzo-fusion
ctest --test-dir "$tsan" --output-on-failure -j "$jobs" --timeout 10800 -R '^(SessionManager|RestServerTest|GrpcServerTest|SessionRecording|MappingEndpointsTest|Session)\.'
