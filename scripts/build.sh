#!/usr/bin/env bash
# Configures and builds toposlice (Release, warnings as errors) into ./build.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOPOSLICE_WERROR=ON "$@" >/dev/null
cmake --build "$build_dir" --parallel "$(nproc)"
