#!/usr/bin/env bash
# VDB masks as a user sees them (issue "VDB: a volume, as a user expects one"):
#   tests/vdb_blender_check.sh [BUILD_DIR]        (default: build)
# Slices examples/example_part.stl (binary and anti-aliased) and a shared mesh to .vdb and .sl1, then
# - Blender 3.4 (Debian `blender`, headless) imports each .vdb as one volume with one grid whose
#   surface has the model's bounds within one voxel (tests/vdb_blender_check.py);
# - every layer k of the grid equals layer k of the .sl1 pixel for pixel (BUILD_DIR/tests/vdb_sl1_check,
#   which reads the grid with OpenVDB: Debian's python3-openvdb cannot read mask grids).
# Installs blender when missing (as root). Prints one PASS or FAIL line per check and a final verdict;
# exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
bin=$build/tools/toposlice
checker=$build/tests/vdb_sl1_check
models=${TOPOSLICE_MODELS_DIR:-../shared/models}
for f in "$bin" "$checker"; do
  [[ -x $f ]] || { echo "FAIL: $f not built (cmake --build $build)"; exit 1; }
done
if ! command -v blender >/dev/null; then
  if [[ $(id -u) -ne 0 ]]; then
    echo "FAIL: blender is not installed (apt-get install blender, as root)"
    exit 1
  fi
  echo "installing blender (Debian package)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q -o DPkg::Lock::Timeout=600 --no-install-recommends \
    blender >/dev/null
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failed=0
checks=0

# case NAME MODEL ARGS...: slices MODEL to NAME.vdb and NAME.sl1 with ARGS, then checks both halves.
case_() {
  local name=$1 model=$2
  shift 2
  "$bin" slice "$model" "$@" --printer sl1 --masks "$tmp/$name.vdb" --summary "$tmp/$name.json" -q
  # The SL1 in the grid's landscape frame: the sl1 preset's display is portrait (PrusaSlicer's), the VDB
  # a volume in the model's frame.
  "$bin" slice "$model" "$@" --printer sl1 --set display_orientation=landscape --set display_mirror_x=0 \
    --masks "$tmp/$name.sl1" -q
  local bounds
  bounds=$(python3 -c 'import json, sys
b = json.load(open(sys.argv[1]))["bounds_mm"]
print(",".join(repr(v) for v in b["min"] + b["max"]))' "$tmp/$name.json")
  local out
  out=$(blender -b --factory-startup --python tests/vdb_blender_check.py -- "$tmp/$name.vdb" "$bounds" 2>&1) || true
  if grep -q '^PASS' <<<"$out"; then
    grep '^PASS' <<<"$out"
  else
    grep '^FAIL' <<<"$out" || { echo "FAIL: blender $name.vdb: no verdict"; tail -20 <<<"$out"; }
    failed=$((failed + 1))
  fi
  "$checker" "$tmp/$name.vdb" "$tmp/$name.sl1" || failed=$((failed + 1))
  checks=$((checks + 2))
}

case_ part examples/example_part.stl -H 0.05
case_ part_aa examples/example_part.stl -H 0.1 --antialias
# A shared mesh, at a layer height fine enough that its slices reach the mesh's extremes within a
# voxel (femur_S001_sub2 at 0.25 mm does not: its widest point lies between two planes).
aligner=$models/derived/aligner_upper_case0.stl.gz
if [[ -f $aligner ]]; then
  case_ aligner "$aligner" -H 0.05
else
  echo "note: $aligner not found: shared-mesh case skipped"
fi

if [[ $failed -ne 0 ]]; then
  echo "FAIL: vdb_blender_check: $failed of $checks checks failed"
  exit 1
fi
echo "PASS: vdb_blender_check: all $checks checks passed"
