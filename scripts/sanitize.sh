#!/usr/bin/env bash
# Sanitizer builds of the test suite:
#   scripts/sanitize.sh address   AddressSanitizer + UndefinedBehaviorSanitizer, the whole suite
#   scripts/sanitize.sh thread    ThreadSanitizer, the tests that run the parallel engine
# Each builds into build-<mode> (Debug-level optimisation -O1, assertions on) and runs ctest there.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=${1:?usage: scripts/sanitize.sh address|thread}
case "$mode" in
  address) sanitize="address,undefined" ;;
  thread) sanitize="thread" ;;
  *) echo "usage: scripts/sanitize.sh address|thread" >&2; exit 2 ;;
esac
./scripts/install-deps.sh
dir=build-$mode
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" \
  -DTOPOSLICE_WERROR=ON -DTOPOSLICE_BUILD_BENCH=OFF -DTOPOSLICE_SANITIZE="$sanitize" >/dev/null
cmake --build "$dir" --parallel "$(nproc)"
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export ASAN_OPTIONS=detect_leaks=1
export TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$(pwd)/scripts/tsan.supp"
if [ "$mode" = thread ]; then
  # The parallel engine: split weld, adjacency and STL parse, the streamed gzip read, bands, pipeline,
  # thread-count determinism, Embree queries, batch jobs.
  ctest --test-dir "$dir" --output-on-failure --parallel "$(nproc)" \
    -R 'Split(Topology|Stl)|StreamedGzip|BackgroundTask|Sl1Archive.Deferred|SliceAnalytic|SliceModels.*(femur|tibia)|EmbreeQueries.Concurrent|CliTool.*(Determin|Batch)'
else
  ctest --test-dir "$dir" --output-on-failure --parallel "$(nproc)" -E 'CliTool.*Interrupt'
fi
