#!/usr/bin/env bash
# CI test of toposlice-mpi (README, "Many machines (MPI)"): a batch of the knee femur variants
# (template S001; variants S002, S003, mean, plus the tibia, which has other connectivity and must
# fail) sliced by `toposlice batch` on one process and by `toposlice-mpi batch` on 3 ranks over
# loopback TCP only; the outputs must be byte-identical, the failure reported, the exit status 1 in both.
# Then one output is deleted and the MPI job run again: only that variant is sliced, the result is
# identical again. Also -np 1 against the single runner.
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
run_mpi() {  # run_mpi NP JOB OUTFILE
  timeout 300 mpirun --allow-run-as-root --oversubscribe --bind-to none -np "$1" \
    --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
    "$mpi" batch "$2" >"$3" 2>&1
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

finish
