#!/usr/bin/env bash
# Batch throughput of toposlice-mpi with 1, 2 and 4 ranks on this machine, over loopback TCP
# (README, "Many machines (MPI)"; results in docs/BENCHMARKS.md).
#
# The job: 20 variants of the upper aligner template (aligner_upper_case0, 545k facets), listing
# derived/aligner_upper_case0.stl.gz and derived/aligner_upper_case0_stage2.stl.gz alternately (10
# each, each with its own output path), contours only (.cli; the batch job format writes ASCII CLI),
# at 0.01 mm layers (about 1,100 layers per variant: a run of 20 takes well under a minute per
# configuration on 2 cores; the 1 um layers of production would take hours). The template table is
# built once before timing. Configurations: ranks x threads = cores where possible (1 x cores,
# 2 x cores/2, 4 x cores/4, at least 1 thread, so 4 x 1 oversubscribes 2 cores) and 1 thread per
# rank, each started with
#   mpirun --bind-to none -np R toposlice-mpi batch JOB --threads T
# on a fresh output folder. Printed per configuration: wall seconds of the whole mpirun (MPI start-up
# and teardown included), variants per minute from that, variants per minute from the job's own
# summary (rank 0's clock: table loads and slicing), CPU seconds (user + system, all ranks) per
# variant, which other load on the machine hardly changes, and whether the outputs are byte-identical to
# the first configuration's. The first row is `toposlice batch` (one process, all cores) for reference.
#
# Usage: bench/mpi_scaling.sh [BUILD_DIR] [LAYER_HEIGHT_MM]   (defaults: build, 0.01)
# Environment: TOPOSLICE_MODELS_DIR (default ../shared/models beside the checkout), BENCH_DIR (work
# folder, default a temporary one, removed at the end; up to 2 GB of outputs at a time), BENCH_REPEAT
# (runs per configuration, default 1; the fastest is printed). The load average before each row is
# printed too: on a shared machine, other work changes these numbers more than anything here.
set -euo pipefail

repo="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-build}"
[[ "$build" = /* ]] || build="$repo/$build"
height="${2:-0.01}"
models="$(cd "${TOPOSLICE_MODELS_DIR:-$repo/../shared/models}" && pwd)"
single="$build/tools/toposlice"
mpi="$build/tools/toposlice-mpi"
command -v mpirun >/dev/null || { echo "mpi_scaling: mpirun is not installed (scripts/install-deps.sh)"; exit 1; }
[ -x "$mpi" ] || { echo "mpi_scaling: $mpi is missing (built when CMake finds MPI)"; exit 1; }

a="$models/derived/aligner_upper_case0.stl.gz"
b="$models/derived/aligner_upper_case0_stage2.stl.gz"
if [ -n "${BENCH_DIR:-}" ]; then
  work="$BENCH_DIR"
  mkdir -p "$work"
else
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
fi

{
  printf '{\n  "version": 1,\n  "description": "mpi_scaling: 20 aligner variants, %s mm layers",\n' "$height"
  printf '  "template": {"model": "%s", "table": "aligner_upper_case0.topo"},\n' "$a"
  printf '  "settings": {"layer_height": %s, "method": "sr"},\n  "variants": [\n' "$height"
  for i in $(seq 1 20); do
    if [ $((i % 2)) -eq 1 ]; then m="$a"; else m="$b"; fi
    sep=","
    [ "$i" -eq 20 ] && sep=""
    printf '    {"name": "v%02d", "model": "%s", "contours": "out/v%02d.cli"}%s\n' "$i" "$m" "$i" "$sep"
  done
  printf '  ]\n}\n'
} >"$work/job.json"

rm -f "$work/aligner_upper_case0.topo"
"$single" template "$a" -o "$work/aligner_upper_case0.topo" --quiet
cat "$a" "$b" >/dev/null  # page cache

cores="$(nproc)"
configs=("single:$cores")  # toposlice batch, the single-machine runner, for reference
for r in 1 2 4; do
  t=$((cores / r))
  [ "$t" -ge 1 ] || t=1
  configs+=("$r:$t")
done
for r in 1 2 4; do
  [[ " ${configs[*]} " == *" $r:1 "* ]] || configs+=("$r:1")
done

echo "mpi_scaling: $(mpirun --version 2>&1 | head -n 1); $cores cores; 20 aligner variants at $height mm"
repeat="${BENCH_REPEAT:-1}"
printf '%-6s %-8s %8s %9s %12s %9s %10s %6s\n' ranks threads "wall s" "var/min" "job var/min" "cpu s/v" identical load
reference=""
for c in "${configs[@]}"; do
  r="${c%%:*}"
  t="${c##*:}"
  load="$(cut -d' ' -f1 /proc/loadavg)"
  best=""
  best_rate=""
  for _ in $(seq 1 "$repeat"); do
    rm -rf "$work/out"
    set +e
    TIMEFORMAT='%R %U %S'
    { time {
      if [ "$r" = single ]; then
        "$single" batch "$work/job.json" --threads "$t" >"$work/run.log" 2>&1
      else
        mpirun --allow-run-as-root --oversubscribe --bind-to none -np "$r" \
          --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
          "$mpi" batch "$work/job.json" --threads "$t" >"$work/run.log" 2>&1
      fi
      echo $? >"$work/rc"
    }; } 2>"$work/time"
    set -e
    rc="$(cat "$work/rc")"
    if [ "$rc" -ne 0 ] || [ "$(ls "$work/out"/*.cli 2>/dev/null | wc -l)" -ne 20 ] ||
      ! grep -q '^summary    : 20 sliced, 0 already complete, 0 failed' "$work/run.log"; then
      echo "mpi_scaling: $r ranks x $t threads failed (exit $rc):"
      cat "$work/run.log"
      exit 1
    fi
    read -r wall user sys <"$work/time"
    if [ -z "$best" ] || awk -v a="$wall" -v b="$best" 'BEGIN { exit !(a < b) }'; then
      best="$wall"
      best_cpu="$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", (u + s) / 20 }')"
      best_rate="$(sed -n 's/^summary    : .*(\([0-9.]*\) variants\/min).*/\1/p' "$work/run.log")"
    fi
  done
  sums="$(cd "$work/out" && md5sum v*.cli | md5sum | cut -d' ' -f1)"
  [ -n "$reference" ] || reference="$sums"
  same=no
  [ "$sums" = "$reference" ] && same=yes
  awk -v r="$r" -v t="$t" -v w="$best" -v j="$best_rate" -v c="$best_cpu" -v same="$same" -v l="$load" \
    'BEGIN { printf "%-6s %-8s %8.1f %9.1f %12s %9s %10s %6s\n", r, t, w, 20 * 60 / w, j, c, same, l }'
done
rm -rf "$work/out"
