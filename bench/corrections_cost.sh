#!/usr/bin/env bash
# What the print corrections cost (docs/BENCHMARKS.md, "Cost of the corrections"):
#   bench/corrections_cost.sh [BUILD_DIR]
# Slices the aligner at 1 um into SL1 masks with and without every correction, alternating the two runs
# REPEAT times (default 8), and prints each run's median (min-max) wall time, its CPU time (user +
# sys, steadier than the wall time on a shared machine) and the ratios. "Every
# correction" is the issue's set on anti-aliased masks: --absolute-correction 0.05
# --elefant-foot-compensation 0.2 --relative-correction-x/y 1.02 --gamma-correction 0.8 and a light map
# (a 1440 x 2560 ramp from 200 to 255 along the long side, written here). BINARY=1 adds the binary pair
# (the same corrections without gamma and light map, which only anti-aliased masks have).
# Environment: REPEAT, THREADS (default: all cores), HEIGHT (mm, default 0.001), MODEL (default the
# aligner). Outputs go to a temporary folder that is removed at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
bin=$build/tools/toposlice
model=${MODEL:-${TOPOSLICE_MODELS_DIR:-../shared/models}/derived/aligner_upper_case0.stl.gz}
repeat=${REPEAT:-8}
threads=${THREADS:-$(nproc)}
height=${HEIGHT:-0.001}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
[ -x "$bin" ] || { echo "no $bin: build first (scripts/build.sh)"; exit 1; }
[ -f "$model" ] || { echo "no model $model (set MODEL or TOPOSLICE_MODELS_DIR)"; exit 1; }
command -v /usr/bin/time >/dev/null || { echo "needs /usr/bin/time (apt-get install time)"; exit 1; }

# The light map: 8-bit grayscale PNG, 1440 wide and 2560 tall (the SL1's portrait images).
python3 - "$out/light.png" <<'EOF'
import struct, sys, zlib
w, h = 1440, 2560
rows = b"".join(b"\0" + bytes([200 + 55 * y // (h - 1)]) * w for y in range(h))
def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
png += chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")
open(sys.argv[1], "wb").write(png)
EOF

corrections=(--absolute-correction 0.05 --elefant-foot-compensation 0.2 --relative-correction-x 1.02
  --relative-correction-y 1.02)
every=(--antialias "${corrections[@]}" --gamma-correction 0.8 --light-map "$out/light.png")
labels=("anti-aliased, no corrections" "anti-aliased, every correction")
args=("--antialias" "${every[*]}")
if [ "${BINARY:-0}" = 1 ]; then
  labels+=("binary, no corrections" "binary, absolute + elephant foot + relative")
  args+=("" "${corrections[*]}")
fi

machine="$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), from $(date -u '+%F %H:%M UTC'), load $(cut -d' ' -f1-3 /proc/loadavg) at the start"
for _ in $(seq "$repeat"); do
  for i in "${!labels[@]}"; do
    # shellcheck disable=SC2086 # the run's options, split as written above (the paths have no spaces)
    /usr/bin/time -f "%e %U %S" -o "$out/time" \
      "$bin" slice "$model" -H "$height" --printer sl1 --masks "$out/m$i.sl1" --threads "$threads" -q --force \
      ${args[$i]}
    read -r wall user sys < "$out/time"
    echo "$i $wall $(awk "BEGIN{printf \"%.2f\", $user + $sys}")" >> "$out/times"
  done
done

echo "machine: $machine, to $(date -u '+%H:%M UTC')"
echo "model $(basename "$model"), -H $height, SL1 grid, --threads $threads, $repeat rounds alternating"
echo
python3 - "$out/times" "${labels[@]}" <<'EOF'
import statistics, sys
times, cpus = {}, {}
for line in open(sys.argv[1]):
    i, wall, cpu = line.split()
    times.setdefault(int(i), []).append(float(wall))
    cpus.setdefault(int(i), []).append(float(cpu))
labels = sys.argv[2:]
print("| run | median wall (min-max) | wall vs the same masks without corrections | median CPU (user + sys) | CPU vs without |")
print("|---|---:|---:|---:|---:|")
for i, label in enumerate(labels):
    t, c = times[i], cpus[i]
    base, cbase = times[i - i % 2], cpus[i - i % 2]
    ratio = statistics.median(t) / statistics.median(base)
    pairs = statistics.median(a / b for a, b in zip(t, base))
    cost = "1" if i % 2 == 0 else f"{ratio:.3f}x (median of the rounds' ratios {pairs:.3f}x)"
    ccost = "1" if i % 2 == 0 else f"{statistics.median(c) / statistics.median(cbase):.3f}x"
    print(f"| {label} | {statistics.median(t):.2f} s ({min(t):.2f}-{max(t):.2f}) | {cost} | "
          f"{statistics.median(c):.2f} s | {ccost} |")
EOF
