#!/usr/bin/env bash
# The print settings of an SL1 archive as PrusaSlicer reads them (issue "Production print settings":
# exposure and correction settings round-trip into the SL1 and are what PrusaSlicer's SL1 import reads):
#   tests/prusa_ini_check.sh [BUILD_DIR]        (default: build)
# PrusaSlicer 2.5's SLA archive import (import_sla_archive) loads the archive's prusaslicer.ini with its
# config loader, the same one `--load` uses; its CLI has no archive import. So each case slices
# examples/example_part.stl to an .sl1 with non-default settings, then `prusa-slicer --load` reads the
# archive's prusaslicer.ini and `--save` writes back what it understood. Checked:
# - every key toposlice writes comes back with the same value (a key PrusaSlicer does not know is dropped
#   by its loader; a value it cannot parse fails the load or is substituted, and then differs);
# - each setting given on the command line is in the archive with the value given, in prusaslicer.ini
#   and, for the firmware's keys, in config.ini.
# Installs prusa-slicer when missing (as root). One PASS or FAIL line per check; exits non-zero on any.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
bin=$build/tools/toposlice
[[ -x $bin ]] || { echo "FAIL: $bin not built (cmake --build $build)"; exit 1; }
if ! command -v prusa-slicer >/dev/null; then
  if [[ $(id -u) -ne 0 ]]; then
    echo "FAIL: prusa-slicer is not installed (apt-get install prusa-slicer, as root)"
    exit 1
  fi
  echo "installing prusa-slicer (Debian package)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q -o DPkg::Lock::Timeout=600 --no-install-recommends \
    prusa-slicer >/dev/null
fi
command -v unzip >/dev/null || { echo "FAIL: unzip is not installed"; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failed=0
checks=0
pass() { echo "PASS: $*"; checks=$((checks + 1)); }
fail() { echo "FAIL: $*"; checks=$((checks + 1)); failed=$((failed + 1)); }

# value FILE KEY: the value of "KEY = value" in an ini file (empty when absent).
value() { awk -v k="$2" -F' = ' '$1 == k { print $2; exit }' "$1"; }

# case NAME EXPECT ARGS...: slices the example part with ARGS; EXPECT is a space-separated list of
# file:key=value that the archive must hold (file: p = prusaslicer.ini, c = config.ini).
case_() {
  local name=$1 expect=$2
  shift 2
  local dir=$tmp/$name
  mkdir -p "$dir"
  "$bin" slice examples/example_part.stl -H 0.05 --masks "$dir/part.sl1" -q "$@"
  unzip -p "$dir/part.sl1" prusaslicer.ini > "$dir/ours.ini"
  unzip -p "$dir/part.sl1" config.ini > "$dir/config.ini"
  if ! prusa-slicer --loglevel 1 --load "$dir/ours.ini" --save "$dir/back.ini" > "$dir/prusa.log" 2>&1; then
    fail "$name: prusa-slicer cannot load the archive's prusaslicer.ini: $(grep -v '^\[' "$dir/prusa.log" | head -3)"
    return
  fi
  local key ours back lost=()
  while IFS= read -r line; do
    [[ $line == *" = "* ]] || continue
    key=${line%% = *}
    ours=${line#* = }
    back=$(value "$dir/back.ini" "$key")
    [[ $back == "$ours" ]] || lost+=("$key ('$ours' read back as '$back')")
  done < "$dir/ours.ini"
  if [[ ${#lost[@]} -eq 0 ]]; then
    pass "$name: PrusaSlicer reads all $(grep -c ' = ' "$dir/ours.ini") keys of prusaslicer.ini back unchanged"
  else
    fail "$name: PrusaSlicer reads back differently: ${lost[*]}"
  fi
  local item file kv got wrong=()
  for item in $expect; do
    file=${item%%:*}
    kv=${item#*:}
    key=${kv%%=*}
    case $file in p) got=$(value "$dir/ours.ini" "$key") ;; c) got=$(value "$dir/config.ini" "$key") ;; esac
    [[ $got == "${kv#*=}" ]] || wrong+=("$file:$key is '$got', not '${kv#*=}'")
  done
  if [[ ${#wrong[@]} -eq 0 ]]; then
    pass "$name: the archive holds the settings given ($expect)"
  else
    fail "$name: ${wrong[*]}"
  fi
}

case_ defaults "p:exposure_time=8 p:initial_exposure_time=35 p:faded_layers=10 c:expTime=8 c:expTimeFirst=35 c:numFade=10" \
  --printer sl1
case_ exposure "p:exposure_time=6.5 p:initial_exposure_time=30 p:faded_layers=7 c:expTime=6.5 c:expTimeFirst=30 c:numFade=7" \
  --printer sl1 --set exposure_time=6.5 --set initial_exposure_time=30 --set faded_layers=7
case_ corrections \
  "p:absolute_correction=0.03 p:elefant_foot_compensation=0.1 p:elefant_foot_min_width=0.3 p:relative_correction_x=1.01 p:relative_correction_y=0.99 p:relative_correction_z=1.02 p:material_correction_x=1.005 p:material_correction_y=1.004 p:material_correction_z=0.998" \
  --printer sl1 --absolute-correction 0.03 --elefant-foot-compensation 0.1 --set elefant_foot_min_width=0.3 \
  --relative-correction-x 1.01 --relative-correction-y 0.99 --relative-correction-z 1.02 \
  --set material_correction_x=1.005 --set material_correction_y=1.004 --set material_correction_z=0.998
case_ antialiased_sl1s "p:gamma_correction=0.8 p:printer_model=SL1S c:printerModel=SL1S p:display_mirror_x=1" \
  --printer sl1s --antialias --set gamma_correction=0.8 --mirror-x

if [[ $failed -eq 0 ]]; then
  echo "PASS: prusa_ini_check: all $checks checks passed"
else
  echo "FAIL: prusa_ini_check: $failed of $checks checks failed"
  exit 1
fi
