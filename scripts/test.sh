#!/usr/bin/env bash
# Install what is missing, build, and run the whole test suite (ctest). The shared test meshes are read
# from ../shared/models beside the checkout.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
ctest --test-dir build --output-on-failure --parallel "$(nproc)"
