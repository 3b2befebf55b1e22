#!/usr/bin/env bash
# CI test of toposlice-mpi (README, "Many machines (MPI)"): a batch of the knee femur variants
# (template S001; variants S002, S003, mean, plus the tibia, which has other connectivity and must
# fail) sliced by `toposlice batch` on one process and by `toposlice-mpi batch` on 3 ranks over
# loopback TCP only; the outputs must be byte-identical, the failure reported, the exit status 1 in both.
# Then one output is deleted and the MPI job run again: only that variant is sliced, the result is
# identical again. Also -np 1 against the single runner.
# Then the warnings of variants sliced on other ranks reach rank 0's stderr (with --quiet too).
# Then a plate job (the bundled plate example on a small plate, so that it spills over to 4 plates):
# `toposlice-mpi plate` on 2 and 3 ranks writes the same bytes as `toposlice plate` (the report too, but
# for its seconds); an output in the way and overlapping placements fail with one error and leave
# nothing behind.
#
# Usage: tests/mpi_batch_test.sh [BUILD_DIR]   (default: build; builds nothing)
# Skips (exit 0) when mpirun is not installed. Last line: "N passed, M failed".
set -uo pipefail

repo="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-build}"
[[ "$build" = /* ]] || build="$repo/$build"
models="${TOPOSLICE_MODELS_DIR:-$repo/../shared/models}"

if ! command -v mpirun >/dev/null 2>&1; then
  echo "mpi_batch_test: skipped: mpirun is not installed (scripts/install-deps.sh installs openmpi-bin)"
  echo "0 passed, 0 failed, 1 skipped"
  exit 0
fi

passed=0
failed=0
check() {  # check NAME COMMAND...: runs the command, counts and prints the result
  local name="$1"
  shift
  if "$@" >/dev/null 2>&1; then
    passed=$((passed + 1))
    echo "  ok   $name"
  else
    failed=$((failed + 1))
    echo "  FAIL $name"
  fi
}
finish() {
  echo "$passed passed, $failed failed"
  [ "$failed" -eq 0 ]
  exit $?
}

single="$build/tools/toposlice"
mpi="$build/tools/toposlice-mpi"
for f in "$single" "$mpi"; do
  if [ ! -x "$f" ]; then
    echo "mpi_batch_test: $f is missing (toposlice-mpi is built when CMake finds MPI: libopenmpi-dev)"
    failed=$((failed + 1))
    finish
  fi
done
for m in knee_femur_ssm_S001 knee_femur_ssm_S002 knee_femur_ssm_S003 knee_femur_ssm_mean knee_tibia_ssm_S001; do
  if [ ! -f "$models/$m.stl" ]; then
    echo "mpi_batch_test: $models/$m.stl is missing (the shared models are read from ../shared/models)"
    failed=$((failed + 1))
    finish
  fi
done
models="$(cd "$models" && pwd)"

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# One job file per run, outputs relative to the job file: A (single process), B (3 ranks), C (1 rank).
write_job() {
  mkdir -p "$1"
  cat >"$1/job.json" <<EOF
{
  "version": 1,
  "description": "mpi_batch_test: knee femur variants, 0.5 mm layers, SL1 masks",
  "template": {"model": "$models/knee_femur_ssm_S001.stl", "table": "out/femur_S001.topo"},
  "settings": {"layer_height": 0.5, "printer": "sl1"},
  "variants": [
    {"name": "S002", "model": "$models/knee_femur_ssm_S002.stl", "contours": "out/S002.cli", "masks": "out/S002.sl1"},
    {"name": "S003", "model": "$models/knee_femur_ssm_S003.stl", "contours": "out/S003.cli", "masks": "out/S003.sl1"},
    {"name": "tibia", "model": "$models/knee_tibia_ssm_S001.stl", "contours": "out/tibia.cli", "masks": "out/tibia.sl1"},
    {"name": "mean", "model": "$models/knee_femur_ssm_mean.stl", "contours": "out/mean.cli", "masks": "out/mean.sl1"}
  ]
}
EOF
}
for d in A B C; do write_job "$tmp/$d"; done

# Loopback only: TCP between ranks (no shared-memory transport), the runtime's own traffic on lo too.
export OMPI_MCA_btl_tcp_if_include=lo OMPI_MCA_oob_tcp_if_include=lo
run_mpi() {  # run_mpi NP JOB OUTFILE [COMMAND]: COMMAND is batch (default) or plate
  timeout 300 mpirun --allow-run-as-root --oversubscribe --bind-to none -np "$1" \
    --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
    "$mpi" "${4:-batch}" "$2" >"$3" 2>&1
}
same_outputs() {  # same_outputs DIR1 DIR2: every femur output present in both and byte-identical
  local f
  for f in S002.cli S002.sl1 S003.cli S003.sl1 mean.cli mean.sl1 femur_S001.topo; do
    [ -s "$1/out/$f" ] && cmp -s "$1/out/$f" "$2/out/$f" || return 1
  done
}
status_of() {  # status_of LOG VARIANT: the status column of the variant's summary line
  awk -v n="$2" '$1 == n && $2 == ":" { print $3 }' "$1"
}

echo "mpi_batch_test: $(mpirun --version 2>&1 | head -n 1); build $build; models $models"

timeout 300 "$single" batch "$tmp/A/job.json" >"$tmp/A.log" 2>&1
rc_a=$?
run_mpi 3 "$tmp/B/job.json" "$tmp/B.log"
rc_b=$?
echo "--- toposlice-mpi, 3 ranks:"
sed 's/^/    /' "$tmp/B.log"

check "single process exits 1 (tibia fails), got $rc_a" test "$rc_a" -eq 1
check "3 ranks exit 1 (tibia fails), got $rc_b" test "$rc_b" -eq 1
check "single process sliced the femur variants" test "$(status_of "$tmp/A.log" S002)$(status_of "$tmp/A.log" S003)$(status_of "$tmp/A.log" mean)" = okokok
check "3 ranks sliced the femur variants" test "$(status_of "$tmp/B.log" S002)$(status_of "$tmp/B.log" S003)$(status_of "$tmp/B.log" mean)" = okokok
check "3 ranks: summary names tibia as failed" test "$(status_of "$tmp/B.log" tibia)" = failed
check "3 ranks: the failure says why (connectivity)" grep -q "^tibia .*does not share the template's connectivity" "$tmp/B.log"
check "3 ranks: summary has a rank column" grep -Eq '^S002 +: ok +[0-9.]+ s  rank [0-9]' "$tmp/B.log"
check "3 ranks: totals line" grep -q "^summary    : 3 sliced, 0 already complete, 1 failed of 4;.*3 ranks" "$tmp/B.log"
check "outputs byte-identical: single process vs 3 ranks" same_outputs "$tmp/A" "$tmp/B"
check "no tibia outputs and no temporaries left" test -z "$(ls "$tmp/B/out" | grep -E 'tibia|\.tmp-')"
ranks_used="$(awk '$2 == ":" && $3 == "ok" && $6 == "rank" { print $7 }' "$tmp/B.log" | sort -u | tr '\n' ' ')"
echo "    (variants were sliced on ranks: $ranks_used)"

# Re-run after losing one output: only that variant is sliced again.
rm -f "$tmp/B/out/S003.sl1"
run_mpi 3 "$tmp/B/job.json" "$tmp/B2.log"
rc_b2=$?
echo "--- toposlice-mpi, 3 ranks, after deleting out/S003.sl1:"
sed 's/^/    /' "$tmp/B2.log"
check "re-run exits 1 (tibia still fails), got $rc_b2" test "$rc_b2" -eq 1
check "re-run slices S003 again" test "$(status_of "$tmp/B2.log" S003)" = ok
check "re-run reports S002 and mean complete" test "$(status_of "$tmp/B2.log" S002)$(status_of "$tmp/B2.log" mean)" = completecomplete
check "re-run totals: 1 sliced, 2 complete, 1 failed" grep -q "^summary    : 1 sliced, 2 already complete, 1 failed of 4;" "$tmp/B2.log"
check "re-run loads the saved table" grep -q "^template   : .*table loaded " "$tmp/B2.log"
check "outputs byte-identical again after the re-run" same_outputs "$tmp/A" "$tmp/B"

# One rank: the single-machine runner's behaviour.
run_mpi 1 "$tmp/C/job.json" "$tmp/C.log"
rc_c=$?
check "1 rank exits 1, got $rc_c" test "$rc_c" -eq 1
check "1 rank: outputs byte-identical to the single process" same_outputs "$tmp/A" "$tmp/C"
check "1 rank: every variant on rank 0" test "$(awk '$2 == ":" && $3 == "ok" { print $7 }' "$tmp/C.log" | sort -u)" = 0

# Warnings travel to rank 0: inside-out variants (the example part turned over, with its own table) are
# a warning each, naming the variant, even with --quiet, from whichever rank sliced them.
mkdir -p "$tmp/W"
python3 - "$repo/examples/example_part.stl" "$tmp/W/inv.stl" <<'PY'
import struct, sys
d = open(sys.argv[1], 'rb').read()
n = struct.unpack('<I', d[80:84])[0]
out = bytearray(d[:84])
for i in range(n):
    r = d[84 + 50 * i:134 + 50 * i]
    out += r[0:12] + r[12:24] + r[36:48] + r[24:36] + r[48:50]
open(sys.argv[2], 'wb').write(out)
PY
cat >"$tmp/W/job.json" <<'JSON'
{"version": 1, "template": {"model": "inv.stl"}, "settings": {"layer_height": 0.5},
 "variants": [{"name": "turned1", "model": "inv.stl", "contours": "w1.cli"},
              {"name": "turned2", "model": "inv.stl", "contours": "w2.cli"},
              {"name": "turned3", "model": "inv.stl", "contours": "w3.cli"}]}
JSON
timeout 300 mpirun --allow-run-as-root --oversubscribe --bind-to none -np 2 \
  --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
  "$mpi" batch "$tmp/W/job.json" --quiet >"$tmp/W.out" 2>"$tmp/W.err"
rc_w=$?
check "warnings: 2 ranks exit 0, got $rc_w" test "$rc_w" -eq 0
check "warnings: one per variant on stderr with --quiet" test \
  "$(grep -c "^toposlice-mpi: warning: variant 'turned[123]': .*inv.stl: the mesh is inside out" "$tmp/W.err")" -eq 3

# --quiet with a failing variant, as toposlice batch -q: no table, one error line naming the variant on
# stderr; and no progress lines when stderr is not a terminal. --dispatch-only on one rank is an error.
rm -rf "$tmp/C/out"
timeout 300 mpirun --allow-run-as-root --oversubscribe --bind-to none -np 2 \
  --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
  "$mpi" batch "$tmp/C/job.json" --quiet >"$tmp/Q.out" 2>"$tmp/Q.err"
rc_q=$?
check "quiet: exits 1 (tibia fails), got $rc_q" test "$rc_q" -eq 1
check "quiet: nothing on stdout" test ! -s "$tmp/Q.out"
check "quiet: one error line for tibia, no table" test \
  "$(grep -c "^toposlice-mpi: error: variant 'tibia' (.*): .*connectivity" "$tmp/Q.err")" -eq 1 -a \
  "$(grep -c "^summary" "$tmp/Q.err")" -eq 0
check "not a terminal: no progress lines" test "$(grep -c '^toposlice-mpi: \[' "$tmp/B.log")" -eq 0
timeout 60 mpirun --allow-run-as-root --oversubscribe --bind-to none -np 1 \
  --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
  "$mpi" batch "$tmp/C/job.json" --dispatch-only >"$tmp/D.out" 2>&1
rc_d=$?
check "--dispatch-only on 1 rank: refused (exit 2), got $rc_d" test "$rc_d" -eq 2
check "--dispatch-only on 1 rank: says why" grep -q "^toposlice-mpi: error: --dispatch-only .* no other rank" "$tmp/D.out"
timeout 60 mpirun --allow-run-as-root --oversubscribe --bind-to none -np 1 \
  --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
  "$mpi" batch "$tmp/C/job.json" --threads 5000 >"$tmp/T.out" 2>&1
rc_t=$?
check "--threads 5000: refused (exit 2) as in job files, got $rc_t" test "$rc_t" -eq 2
check "--threads 5000: names the bound" grep -q "^toposlice-mpi: error: --threads: must be between 0 (all cores) and 4096" "$tmp/T.out"

# A plate job: the four arches of examples/plate on a 70 x 40 mm plate, one arch per plate, with print
# settings (scaling along the plate's x, absolute correction, elephant foot, exposure). The same job
# file for every run (an SL1 archive is dated by its job file), outputs in P/out, moved aside after each.
plate_dir="$tmp/P"
mkdir -p "$plate_dir/out"
ex="$repo/examples/plate"
cat >"$plate_dir/job.json" <<EOF
{
  "version": 1,
  "description": "mpi_batch_test: the plate example on a small plate, spilling over to several plates",
  "printer": "sl1",
  "material": "default",
  "print_settings": {"relative_correction_x": 1.01, "absolute_correction": 0.02,
                     "elefant_foot_compensation": 0.1, "exposure_time": 5},
  "settings": {"layer_height": 0.5, "pixel": 0.1, "resolution": [700, 400]},
  "arrange": {"spacing": 2, "margin": 3, "rotation_step": 90},
  "parts": [
    {"name": "wide", "model": "$ex/arch_wide.stl", "template": "$ex/arch_template.topo", "placement": "auto"},
    {"name": "wavy", "model": "$ex/arch_wavy.stl", "template": "$ex/arch_template.topo", "placement": "auto"},
    {"name": "named", "model": "$ex/arch_named.stl", "template": "$ex/arch_template.topo",
     "add": ["$ex/arch_named_label.stl"], "placement": "auto"},
    {"name": "plain", "model": "$ex/arch_template.stl", "template": "$ex/arch_template.topo", "placement": "auto"}
  ],
  "outputs": {"masks": "out/p.sl1", "contours": ["out/p.cli", "out/p.svg"], "report": "out/report.json",
              "picture": "out/p.png"}
}
EOF
plate_files="p.cli p.svg p.sl1 p.png p-plate2.cli p-plate2.svg p-plate2.sl1 p-plate2.png
  p-plate3.cli p-plate3.svg p-plate3.sl1 p-plate3.png p-plate4.cli p-plate4.svg p-plate4.sl1 p-plate4.png"
same_plates() {  # same_plates DIR1 DIR2: all 16 plate outputs byte-identical, the reports but for their seconds
  local f
  for f in $plate_files; do
    [ -s "$1/$f" ] && cmp -s "$1/$f" "$2/$f" || return 1
  done
  [ "$(ls "$1" | wc -l)" -eq 17 ] && [ "$(ls "$2" | wc -l)" -eq 17 ] || return 1
  cmp -s <(sed '/"seconds": {/,/}/d' "$1/report.json") <(sed '/"seconds": {/,/}/d' "$2/report.json")
}
timeout 300 "$single" plate "$plate_dir/job.json" >"$tmp/P1.log" 2>&1
rc_p1=$?
mv "$plate_dir/out" "$plate_dir/single" && mkdir "$plate_dir/out"
check "plate: single process exits 0, got $rc_p1" test "$rc_p1" -eq 0
check "plate: the job spills over to 4 plates" grep -q "^4 plates, 4 parts" "$tmp/P1.log"
check "plate: print_settings reach the SL1 (expTime = 5)" python3 -c \
  "import sys, zipfile; sys.exit('expTime = 5\n' not in zipfile.ZipFile(sys.argv[1]).read('config.ini').decode())" \
  "$plate_dir/single/p.sl1"
for np in 2 3; do
  run_mpi "$np" "$plate_dir/job.json" "$tmp/P$np.log" plate
  rc_p=$?
  echo "--- toposlice-mpi plate, $np ranks:"
  sed 's/^/    /' "$tmp/P$np.log"
  check "plate, $np ranks: exits 0, got $rc_p" test "$rc_p" -eq 0
  check "plate, $np ranks: outputs byte-identical to the single process" \
    same_plates "$plate_dir/single" "$plate_dir/out"
  check "plate, $np ranks: plate 2 sliced on rank 1" grep -q "plate 2 on rank 1," "$tmp/P$np.log"
  check "plate, $np ranks: the single process's summary" \
    cmp -s <(grep -v '^read+topology\|^ranks:' "$tmp/P$np.log") <(grep -v '^read+topology' "$tmp/P1.log")
  mv "$plate_dir/out" "$plate_dir/np$np" && mkdir "$plate_dir/out"
done

# Plate 2's contours are in the way (the job does not overwrite): plate 2 is rank 1's, rank 0 reports it
# once, every rank exits 1, and no other output or temporary is left.
echo "not a toposlice file" >"$plate_dir/out/p-plate2.svg"
run_mpi 2 "$plate_dir/job.json" "$tmp/P_exists.log" plate
rc_p=$?
check "plate, an output in the way: 2 ranks exit 1, got $rc_p" test "$rc_p" -eq 1
check "plate, an output in the way: one error naming it" \
  test "$(grep -c '^toposlice-mpi: error: .*p-plate2.svg: already exists' "$tmp/P_exists.log")" -eq 1
check "plate, an output in the way: nothing else written, no temporaries" \
  test "$(ls "$plate_dir/out")" = p-plate2.svg
rm -f "$plate_dir/out/p-plate2.svg"

# Given placements that overlap: refused before slicing, reported once by 3 ranks, nothing written.
# (No part is placed "auto" there, so arrange.rotation_step, which would do nothing, goes too.)
sed -e 's/"placement": "auto"/"placement": {"x": 30, "y": 15}/' -e 's/, "rotation_step": 90//' \
  "$plate_dir/job.json" >"$plate_dir/overlap.json"
run_mpi 3 "$plate_dir/overlap.json" "$tmp/P_overlap.log" plate
rc_p=$?
check "plate, overlapping placements: 3 ranks exit 1, got $rc_p" test "$rc_p" -eq 1
check "plate, overlapping placements: reported once" \
  test "$(grep -c '^toposlice-mpi: error: .*overlap.json: the plate cannot be printed as given' "$tmp/P_overlap.log")" -eq 1
check "plate, overlapping placements: names the parts" grep -q "parts 'wide' and 'wavy' overlap" "$tmp/P_overlap.log"
check "plate, overlapping placements: nothing written" test -z "$(ls "$plate_dir/out")"
# mpirun ends the other ranks when one exits 1: that is no interrupt to report (it was, now and then).
check "plate, overlapping placements: no rank says it was interrupted" \
  test "$(grep -c 'interrupted' "$tmp/P_overlap.log")" -eq 0

finish
