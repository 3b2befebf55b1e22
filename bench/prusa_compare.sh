#!/usr/bin/env bash
# Side by side with PrusaSlicer: the same model, layer height, pixel grid and binary masks, sliced by
# PrusaSlicer (Debian's prusa-slicer, installed here when missing) and by toposlice into SL1 archives;
# reports the pixel agreement per layer and the wall time and peak memory of both.
#
#   bench/prusa_compare.sh [MODEL] [LAYER_HEIGHT]
#       MODEL          STL, optionally .gz (default ../shared/models/derived/aligner_upper_case0.stl.gz)
#       LAYER_HEIGHT   mm (default 0.001)
#   Environment:
#       BUILD_DIR      toposlice build folder (default build/; toposlice and compare_masks are built there
#                      when missing)
#       WORK_DIR       where the archives, logs and the per-layer CSV go (default: a new /tmp/prusa_compare.*)
#       KEEP=0         delete the two archives at the end (default 1: keep them)
#       PRUSA_ORIENTATION, PRUSA_MIRROR_X, PRUSA_MIRROR_Y
#                      PrusaSlicer's display settings (default: the Original Prusa SL1 preset: portrait, 1, 0)
#       TOPO_PORTRAIT=0
#                      toposlice writes landscape images and compare_masks --transpose maps them (the
#                      default, 1, has toposlice write PrusaSlicer's display orientation and mirroring
#                      too, compared as they are)
#       THREADS        toposlice --threads (default: all cores; PrusaSlicer always uses all cores)
#       CORRECTIONS    printer corrections given to both, by their shared names, e.g.
#                      "--absolute-correction 0.05 --elefant-foot-compensation 0.2 --relative-correction-x 1.02"
#                      (PrusaSlicer's option names are toposlice's: see docs/FORMATS.md, "Profile files")
#       FORMATS        toposlice's mask formats to time against PrusaSlicer's SL1 (default "sl1"; any of
#                      sl1 exr vdb goo nanodlp png, "all" for every one): the same job written to each,
#                      one run each after the SL1 comparison, in a table of wall, CPU, peak and size
#       ANTIALIAS=1    anti-aliased masks on both sides: PrusaSlicer --gamma-correction 1 (AGG coverage,
#                      no gamma), toposlice --antialias (exact coverage); compare the sums of pixel values
#
# How the two are made to mean the same thing by pixel (i, j) and layer k:
# - Printer: PrusaSlicer gets the Original Prusa SL1 preset's printer settings (bed 1.48..119.48 x
#   1.02..67.02 mm, display 120.96 x 68.04 mm, 2560 x 1440 px, portrait, display_mirror_x = 1 as the
#   default, display_mirror_y = 0) from a --load file, since 2.5's CLI cannot select a vendor preset.
#   toposlice gets --printer sl1 (2560 x 1440 at 0.04725 mm = 120.96 / 2560 = 68.04 / 1440, portrait,
#   display_mirror_x = 1: the same display) with PrusaSlicer's orientation and mirror flags set by name.
# - Placement: PrusaSlicer rasterizes bed coordinates, bed (0, 0) at the display's corner, so the display
#   covers [0, 120.96] x [0, 68.04] mm. `--center 60.48,34.02 --dont-arrange` moves the model's xy
#   bounding-box centre to the display centre (Model::center_instances_around_point) and does not run the
#   arrangement afterwards. toposlice's default grid is centred on the same bounding-box centre, so pixel
#   (i, j) covers the same square of the model in both; no --origin is needed.
# - Orientation and mirroring (PrusaSlicer's RasterBase::Trafo: mirror_y is inverted so that row 0 is the
#   top; portrait swaps x and y and inverts mirror_x): in landscape, PrusaSlicer's PNG is toposlice's
#   (x right, y up) with display_mirror_x = toposlice --mirror-x and display_mirror_y = --mirror-y. In
#   portrait (the SL1's 1440 x 2560 PNGs), PrusaSlicer's PNG is the transpose of toposlice's: bed x runs
#   up the rows, bed y along the columns; display_mirror_x = 0 then means toposlice --mirror-y and
#   display_mirror_y = 1 means --mirror-x (the SL1 default, 1 / 0, is a plain transpose of the
#   images as stored bottom row first). compare_masks --transpose compares the two that way
#   (TOPO_PORTRAIT=0). By default toposlice writes the portrait images itself (display_orientation =
#   portrait, the same mirror flags) and they are compared as they are.
# - Binary masks: --gamma-correction 0 (AGG coverage thresholded at 1/2; toposlice lights a pixel whose
#   centre is inside: the same for any edge that is straight across the pixel), --slice-closing-radius 0,
#   no supports, no pad (so no elevation), no hollowing, no corrections (defaults).
# - Planes: with initial_layer_height = layer_height = h, PrusaSlicer cuts at bottom + (k + 1/2) h (its
#   SLAPrint slice index: print levels bottom + h + k h in integer nanometres, cut at level - h/2) while
#   the level stays <= top: floor(height / h) layers, the last partial layer dropped. toposlice cuts at
#   z0 + (k + 1/2) h with z0 = the model's lowest z by default: the same planes relative to the model
#   (PrusaSlicer first puts the model on the bed, z = 0). toposlice would make ceil(height / h) layers;
#   it is given PrusaSlicer's count (--layers, read from the archive's config.ini) so both do the same work.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/.." && pwd)
model=${1:-$root/../shared/models/derived/aligner_upper_case0.stl.gz}
h=${2:-0.001}
build=${BUILD_DIR:-$root/build}
work=${WORK_DIR:-$(mktemp -d /tmp/prusa_compare.XXXXXX)}
orientation=${PRUSA_ORIENTATION:-portrait}
mirror_x=${PRUSA_MIRROR_X:-1}
mirror_y=${PRUSA_MIRROR_Y:-0}
keep=${KEEP:-1}
formats=${FORMATS:-sl1}
[ "$formats" = all ] && formats="sl1 exr vdb goo nanodlp png"

die() { echo "prusa_compare: $*" >&2; exit 1; }
[ -f "$model" ] || die "no model file '$model'"
model=$(realpath "$model")
case $orientation in landscape|portrait) ;; *) die "PRUSA_ORIENTATION must be landscape or portrait" ;; esac
case $mirror_x$mirror_y in [01][01]) ;; *) die "PRUSA_MIRROR_X / PRUSA_MIRROR_Y must be 0 or 1" ;; esac
for f in $formats; do
  case $f in sl1|exr|vdb|goo|nanodlp|png) ;; *) die "FORMATS: unknown format '$f' (sl1 exr vdb goo nanodlp png, or all)" ;; esac
done
mkdir -p "$work"
work=$(cd "$work" && pwd)

# --- tools -----------------------------------------------------------------------------------------
sudo=
[ "$(id -u)" -eq 0 ] || sudo=sudo
need=()
command -v prusa-slicer >/dev/null || need+=(prusa-slicer)
[ -x /usr/bin/time ] || need+=(time)
command -v unzip >/dev/null || need+=(unzip)
if [ ${#need[@]} -gt 0 ]; then
  echo "installing ${need[*]} ..."
  $sudo apt-get update -qq
  # PrusaSlicer's CLI export (--export-sla) needs no display: no xvfb.
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
if [ ! -x "$build/tools/toposlice" ] || [ ! -x "$build/bench/compare_masks" ]; then
  [ -f "$build/CMakeCache.txt" ] || cmake -S "$root" -B "$build" -G Ninja >/dev/null
  cmake --build "$build" --target toposlice compare_masks
fi
toposlice=$build/tools/toposlice
compare=$build/bench/compare_masks

# --- model: PrusaSlicer reads no .gz; both get the same plain STL ------------------------------------
name=$(basename "$model")
if [ "$(head -c2 "$model" | od -An -tx1 | tr -d ' ')" = 1f8b ]; then
  name=${name%.gz}
  case $name in *.stl|*.STL) ;; *) name=$name.stl ;; esac
  gzip -dc "$model" > "$work/$name"
  stl=$work/$name
else
  stl=$model
fi
job=${name%.*}

# --- PrusaSlicer ---------------------------------------------------------------------------------------
cat > "$work/sl1_printer.ini" <<EOF
printer_technology = SLA
printer_model = SL1
printer_variant = default
printer_settings_id = Original Prusa SL1
bed_shape = 1.48x1.02,119.48x1.02,119.48x67.02,1.48x67.02
display_width = 120.96
display_height = 68.04
display_pixels_x = 2560
display_pixels_y = 1440
display_orientation = $orientation
display_mirror_x = $mirror_x
display_mirror_y = $mirror_y
max_print_height = 150
printer_correction = 1,1,1
EOF
antialias=${ANTIALIAS:-0}
gamma=0
[ "$antialias" = 1 ] && gamma=1
prusa_out=$work/prusaslicer.sl1
topo_out=$work/toposlice.sl1
rm -f "$prusa_out" "$topo_out"
prusa_cmd=(prusa-slicer --export-sla --load "$work/sl1_printer.ini" --layer-height "$h" --initial-layer-height "$h"
  --gamma-correction "$gamma" --slice-closing-radius 0 --no-supports-enable --no-pad-enable --no-hollowing-enable
  --center 60.48,34.02 --dont-arrange --loglevel 1 ${CORRECTIONS:-} --output "$prusa_out" "$stl")

elapsed_s() {  # "Elapsed (wall clock) time (h:mm:ss or m:ss): 1:02.34" -> seconds
  awk -F': ' '/Elapsed \(wall clock\)/ { n = split($2, t, ":"); s = 0; for (i = 1; i <= n; ++i) s = s * 60 + t[i]; printf "%.2f", s }' "$1"
}
cpu_s() { awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' "$1"; }
peak_mb() { awk -F': ' '/Maximum resident set size/ { printf "%.0f", $2 / 1024 }' "$1"; }

load_before_prusa=$(uptime)
echo "PrusaSlicer: ${prusa_cmd[*]}"
if ! /usr/bin/time -v -o "$work/prusaslicer.time" "${prusa_cmd[@]}" > "$work/prusaslicer.log" 2>&1; then
  tail -20 "$work/prusaslicer.log" >&2
  die "PrusaSlicer failed (log: $work/prusaslicer.log)"
fi
layers=$(unzip -p "$prusa_out" config.ini | awk -F' = ' '$1 == "numFast" { f = $2 } $1 == "numSlow" { s = $2 } END { print f + s }')
[ "$layers" -gt 0 ] || die "PrusaSlicer's archive has no layers"

# --- toposlice -----------------------------------------------------------------------------------------
topo_flags=()
transpose=()
if [ "${TOPO_PORTRAIT:-1}" = 1 ]; then
  # The same display settings by the same names: toposlice writes PrusaSlicer's images.
  topo_flags+=(--set "display_orientation=$orientation" --set "display_mirror_x=$mirror_x"
    --set "display_mirror_y=$mirror_y")
elif [ "$orientation" = landscape ]; then
  topo_flags+=(--set display_orientation=landscape --set display_mirror_x=0)
  [ "$mirror_x" = 1 ] && topo_flags+=(--mirror-x)
  [ "$mirror_y" = 1 ] && topo_flags+=(--mirror-y)
else
  topo_flags+=(--set display_orientation=landscape --set display_mirror_x=0)
  transpose=(--transpose)
  [ "$mirror_x" = 0 ] && topo_flags+=(--mirror-y)
  [ "$mirror_y" = 1 ] && topo_flags+=(--mirror-x)
fi
[ -n "${THREADS:-}" ] && topo_flags+=(--threads "$THREADS")
# shellcheck disable=SC2206  # CORRECTIONS is a list of options, split on purpose
topo_flags+=(${CORRECTIONS:-})
[ "$antialias" = 1 ] && topo_flags+=(--antialias)
topo_cmd=("$toposlice" slice "$stl" --layer-height "$h" --layers "$layers" --printer sl1 "${topo_flags[@]}"
  --masks "$topo_out" --quiet)
load_before_topo=$(uptime)
echo "toposlice: ${topo_cmd[*]}"
/usr/bin/time -v -o "$work/toposlice.time" "${topo_cmd[@]}" > "$work/toposlice.log" 2>&1 ||
  { cat "$work/toposlice.log" >&2; die "toposlice failed"; }

# --- comparison ----------------------------------------------------------------------------------------
compare_cmd=("$compare" "$topo_out" "$prusa_out" "$work/agreement.csv" "${transpose[@]}")
echo "compare: ${compare_cmd[*]}"
"${compare_cmd[@]}" | tee "$work/compare.txt"

pt=$(elapsed_s "$work/prusaslicer.time"); pm=$(peak_mb "$work/prusaslicer.time"); pc=$(cpu_s "$work/prusaslicer.time")
tt=$(elapsed_s "$work/toposlice.time"); tm=$(peak_mb "$work/toposlice.time"); tc=$(cpu_s "$work/toposlice.time")
compared=$(awk '/^layers compared/ { print $3 }' "$work/compare.txt")
agree=$(awk '/^overall agreement/ { print $3 }' "$work/compare.txt")
differ=$(awk '/^overall agreement/ { print substr($5, 2) }' "$work/compare.txt")
read -r amin amed amean < <(awk '/^per-layer agreement/ { print $4, $7, $10 }' "$work/compare.txt")
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", a / b }'; }
{
  echo
  echo "## PrusaSlicer vs toposlice: $(basename "$model"), layer height $h mm, SL1 2560 x 1440 at 0.04725 mm, $([ "$antialias" = 1 ] && echo anti-aliased || echo binary)${CORRECTIONS:+, $CORRECTIONS} masks"
  echo
  echo "| | PrusaSlicer $(dpkg-query -W -f '${Version}' prusa-slicer 2>/dev/null || echo '?') | toposlice | PrusaSlicer / toposlice |"
  echo "|---|---|---|---|"
  echo "| layers written | $layers | $layers | |"
  echo "| wall time | $pt s | $tt s | $(ratio "$pt" "$tt") |"
  echo "| CPU time (user + sys) | $pc s | $tc s | $(ratio "$pc" "$tc") |"
  echo "| peak RSS | $pm MB | $tm MB | $(ratio "$pm" "$tm") (toposlice: $(awk -v a="$pm" -v b="$tm" 'BEGIN { printf "%.1f", 100 * b / a }') %) |"
  echo
  echo "| pixel agreement (lit = value >= 128) | |"
  echo "|---|---|"
  echo "| layers compared | $compared (PrusaSlicer's layer k with toposlice's layer k) |"
  echo "| per layer: min / median / mean | $amin % / $amed % / $amean % |"
  echo "| overall (all pixels of all layers) | $agree % ($differ pixels differ) |"
  echo "| lit pixels summed over layers: toposlice / PrusaSlicer | $(awk -F, 'NR > 1 { a += $6; b += $7 } END { printf "%d / %d (%+.3f %%)", a, b, 100 * (a - b) / b }' "$work/agreement.csv") |"
  values=$(awk '/^pixel value sums/ { sub(/^pixel value sums: /, ""); print }' "$work/compare.txt")
  [ -n "$values" ] && echo "| sums of pixel values (A = toposlice, B = PrusaSlicer) | $values |"
  echo
  echo "- machine: $(nproc) cores, $(awk '/MemTotal/ { printf "%.0f GB", $2 / 1048576 }' /proc/meminfo); load average (1, 5, 15 min) before PrusaSlicer:$(echo "$load_before_prusa" | sed 's/.*load average: */ /'), before toposlice:$(echo "$load_before_topo" | sed 's/.*load average: */ /'), after:$(uptime | sed 's/.*load average: */ /')"
  echo "- PrusaSlicer: ${prusa_cmd[*]}"
  echo "- its --load file: $(grep -v '^$' "$work/sl1_printer.ini" | paste -sd ';' | sed 's/;/; /g')"
  echo "- toposlice:   ${topo_cmd[*]}"
  echo "- compare:     ${compare_cmd[*]}"
  echo "- per-layer CSV: $work/agreement.csv; logs and /usr/bin/time -v output: $work"
} | tee "$work/summary.md"

# --- every other mask format, the same job, against PrusaSlicer's SL1 ------------------------------------
format_out() {  # the output path of format $1 (a PNG stack is a folder)
  case $1 in png) echo "$work/toposlice_png" ;; *) echo "$work/toposlice.$1" ;; esac
}
others=()
for f in $formats; do [ "$f" = sl1 ] || others+=("$f"); done
if [ ${#others[@]} -gt 0 ]; then
  rows=()
  for f in "${others[@]}"; do
    out=$(format_out "$f")
    # --force: replaces only what toposlice wrote there before; anything else in the way is an error.
    cmd=("$toposlice" slice "$stl" --layer-height "$h" --layers "$layers" --printer sl1 "${topo_flags[@]}"
      --masks "$out" --quiet --force)
    echo "toposlice ($f): ${cmd[*]}"
    /usr/bin/time -v -o "$work/toposlice.$f.time" "${cmd[@]}" > "$work/toposlice.$f.log" 2>&1 ||
      { cat "$work/toposlice.$f.log" >&2; die "toposlice ($f) failed"; }
    ft=$(elapsed_s "$work/toposlice.$f.time")
    rows+=("| \`.$f\` | $ft s | $(cpu_s "$work/toposlice.$f.time") s | $(peak_mb "$work/toposlice.$f.time") MB | $(du -sb "$out" | cut -f1) B | $(ratio "$pt" "$ft") |")
  done
  {
    echo
    echo "### Every mask format of toposlice against PrusaSlicer's SL1 ($pt s, $pc s CPU, $pm MB)"
    echo
    echo "| toposlice output | wall | CPU (user + sys) | peak RSS | size | PrusaSlicer SL1 wall / this wall |"
    echo "|---|---:|---:|---:|---:|---:|"
    echo "| \`.sl1\` | $tt s | $tc s | $tm MB | $(du -sb "$topo_out" | cut -f1) B | $(ratio "$pt" "$tt") |"
    printf '%s\n' "${rows[@]}"
    echo
    echo "- each: the toposlice command above with --masks $work/toposlice.FORMAT (PNG: a folder) --force; load after: $(uptime | sed 's/.*load average: */ /')"
  } | tee -a "$work/summary.md"
fi

if [ "$keep" = 0 ]; then
  rm -f "$prusa_out" "$topo_out"
  for f in "${others[@]}"; do rm -rf "$(format_out "$f")"; done
fi
