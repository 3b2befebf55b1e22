#!/usr/bin/env bash
# End-to-end measurements of the toposlice command on the derived models (docs/BENCHMARKS.md):
#   bench/e2e.sh [BUILD_DIR]
# Every figure is wall time of the whole command (or the stage times it prints) and peak RSS from
# /usr/bin/time. Runs that are compared are run side by side, alternating, REPEAT times each (default 3),
# and the best is reported. Outputs go to a temporary folder that is removed at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
bin=$build/tools/toposlice
models=${TOPOSLICE_MODELS_DIR:-../shared/models}/derived
repeat=${REPEAT:-3}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
command -v /usr/bin/time >/dev/null || { echo "needs /usr/bin/time (apt-get install time)"; exit 1; }

# run LABEL ARGS...: best wall time and its peak RSS over $repeat runs, plus the stage line of the best.
run() {
  local label=$1
  shift
  local best="" rss="" stages=""
  for _ in $(seq "$repeat"); do
    /usr/bin/time -f "%e %M" -o "$out/time" "$bin" "$@" --force > "$out/log" 2>&1
    read -r wall kb < "$out/time"
    if [ -z "$best" ] || awk "BEGIN{exit !($wall < $best)}"; then
      best=$wall
      rss=$((kb / 1024))
      stages=$(grep -E '^time' "$out/log" | sed 's/^time *: //')
    fi
  done
  printf '| %s | %s s | %s MiB | %s |\n' "$label" "$best" "$rss" "$stages"
}

echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(date -u +%F), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| run | wall | peak RSS | stages (as printed by toposlice) |"
echo "|---|---:|---:|---|"
al=$models/aligner_upper_case0.stl.gz
st=$models/aligner_upper_case0_stage2.stl.gz
sp=$models/spine_L2-L5_sub1.stl.gz
fe=$models/femur_S001_sub2.stl.gz
run "aligner 1 um, sr, slicing only (no output), 2 threads" slice "$al" -H 0.001 --threads 2
run "aligner 1 um, sr, binary CLI written, 2 threads" slice "$al" -H 0.001 --threads 2 -o "$out/al.cli" --cli-binary
run "aligner 1 um, sr, slicing only, 1 thread" slice "$al" -H 0.001 --threads 1
run "aligner 1 um, sr-lazy, slicing only" slice "$al" -H 0.001 --method sr-lazy
"$bin" template "$al" -o "$out/al.topo" --force -q
for threads in 2 1; do
  for i in $(seq "$repeat"); do
    REPEAT=1 run "stage2 1 um from scratch (sr), $threads thread(s)" slice "$st" -H 0.001 --threads "$threads"
    REPEAT=1 run "stage2 1 um with template (sr + .topo), $threads thread(s)" slice "$st" -H 0.001 --threads "$threads" --template "$out/al.topo"
  done
done
# Scaling: the aligner on the SL1 (2560 x 1440 at 0.04725 mm); the spine (95 mm wide) does not fit the
# SL1's 68 mm, so it goes on the generic 4K projector (3840 x 2160) at 0.05 mm.
for model in "$al" "$sp"; do
  name=$(basename "$model" .stl.gz)
  # The spine at 1 um has 145,458 layers, more than an SL1 archive can name (100,000): its masks use
  # 10,000 layers over its height, as the paper's Table 3 does.
  printer=(--printer sl1)
  planes=(-H 0.001)
  [ "$model" = "$sp" ] && printer=(--printer generic-4k --pixel 0.05) && planes=(--layers 10000)
  for threads in 1 2; do
    run "$name 1 um contours only, $threads thread(s)" slice "$model" -H 0.001 --threads "$threads"
  done
  for threads in 1 2 1 2; do
    run "$name ${planes[*]} SL1 masks (${printer[*]}), $threads thread(s)" slice "$model" "${planes[@]}" \
      --threads "$threads" "${printer[@]}" --masks "$out/m.sl1"
  done
done
run "femur_S001_sub2 10,000 layers, binary CLI" slice "$fe" --layers 10000 -o "$out/f.cli" --cli-binary
run "femur_S001_sub2 100,000 layers, binary CLI" slice "$fe" --layers 100000 -o "$out/f.cli" --cli-binary
run "aligner 10,000 layers, SL1 masks" slice "$al" --layers 10000 --printer sl1 --masks "$out/a.sl1"
run "aligner 100,000 layers, SL1 masks" slice "$al" --layers 100000 --printer sl1 --masks "$out/a.sl1"
