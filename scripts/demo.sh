#!/usr/bin/env bash
# The main job on data bundled in the repository: install what is missing, build, then slice a build
# plate of three customized variants of one arch-shaped shell (examples/plate/, one with a label add-on),
# each checked against the template's table and arranged automatically on one Prusa SL1 plate
# (examples/plate_demo.json): one SL1 archive of masks, labelled contours (CLI, SVG), a per-part report
# and a picture of the plate. Outputs go to ./out (or $OUT_DIR); existing ones are replaced.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
out=${OUT_DIR:-out}
mkdir -p "$out"
bin=build/tools/toposlice
"$bin" info examples/plate/arch_template.stl
echo
"$bin" plate examples/plate_demo.json --output-dir "$out"
echo
echo "per-part report : $(cd "$out" && pwd)/plate_demo_report.json"
echo "plate picture   : $(cd "$out" && pwd)/plate_demo.png"
echo "outputs are in $(cd "$out" && pwd)"
