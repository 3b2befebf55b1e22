#!/usr/bin/env bash
# The main job on the bundled example part: install what is missing, build, then slice
# examples/example_part.stl at 10 um layers into contours (ASCII CLI, SVG, 3MF slice stack, binary CLI)
# and projector masks (a Prusa SL1 archive with a per-layer report) and print where every output went.
# Outputs go to ./out (or $OUT_DIR); existing ones are replaced.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
out=${OUT_DIR:-out}
mkdir -p "$out"
bin=build/tools/toposlice
model=examples/example_part.stl
"$bin" info "$model"
echo
"$bin" slice "$model" --layer-height 0.01 --force \
  -o "$out/example_part.cli" -o "$out/example_part.svg" --svg-layers 50,200,400,650 \
  -o "$out/example_part.3mf" --printer sl1 --masks "$out/example_part.sl1" --report "$out/example_part.csv"
"$bin" slice "$model" --layer-height 0.01 --cli-binary --force --quiet -o "$out/example_part_binary.cli"
echo "wrote      : $out/example_part_binary.cli"
echo
echo "outputs are in $(cd "$out" && pwd)"
