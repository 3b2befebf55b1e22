#!/usr/bin/env bash
# Install what is missing, build, and run the whole test suite (ctest). The shared test meshes are read
# from ../shared/models beside the checkout.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -d ../shared/models ]; then
  echo "test.sh: warning: $(cd .. && pwd)/shared/models not found: the tests that read the shared meshes will fail" >&2
fi
./scripts/install-deps.sh
./scripts/build.sh
ctest --test-dir build --output-on-failure --parallel "$(nproc)"
