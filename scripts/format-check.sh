#!/usr/bin/env bash
# Fails when any C++ file differs from the repository's .clang-format (run clang-format -i to fix), or
# when any tracked file still holds a merge-conflict marker.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format >/dev/null; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends clang-format >/dev/null
fi
if git grep -n -E '^(<<<<<<<|>>>>>>>)( |$)|^=======$' -- . ':!*.png' ':!*.stl'; then
  echo "format-check: merge-conflict markers (above) left in tracked files" >&2
  exit 1
fi
git ls-files -z '*.cpp' '*.h' | xargs -0 clang-format --dry-run --Werror
echo "format-check: $(git ls-files '*.cpp' '*.h' | wc -l) files clean"
