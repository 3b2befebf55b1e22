#!/usr/bin/env bash
# The main job on the bundled example part: install what is missing, build, then slice
# examples/example_part.stl at 10 um layers into contours (binary CLI, ASCII CLI, SVG) and print where
# every output went. Outputs go to ./out (or $OUT_DIR); existing ones are replaced.
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
  -o "$out/example_part.cli" -o "$out/example_part.svg" --svg-layers 50,200,400,650
"$bin" slice "$model" --layer-height 0.01 --cli-binary --force --quiet -o "$out/example_part_binary.cli"
echo "wrote      : $out/example_part_binary.cli"
echo
echo "outputs are in $(cd "$out" && pwd)"
