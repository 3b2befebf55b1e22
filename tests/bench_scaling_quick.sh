#!/usr/bin/env bash
# bench/scaling in its quick mode, end to end: three small jobs (a slice with both band starts, a batch,
# the bundled plate), one run each at 1 and 2 threads and 2 one-thread copies at once; the JSON it writes
# must hold a row per job and thread count, both band-start columns, an Amdahl fit per job and the
# copies' row per job. Exit 77 (skip) without the models.
#   tests/bench_scaling_quick.sh PYTHON TOOL MODELS_DIR OUT_DIR
set -euo pipefail
python=$1 tool=$2 models=$3 out=$4
rm -f "$out/scaling.json"
"$python" "$(dirname "$0")/../bench/scaling" --quick --threads 1,2 --repeat 1 --copies 2 \
  --jobs aligner-cli,batch-8,plate --tool "$tool" --models "$models" --out "$out" >/dev/null
for bad in "--copies 1" "--copies 2 --threads 2,4"; do  # option errors: exit 2, before anything runs
  set +e
  "$python" "$(dirname "$0")/../bench/scaling" $bad --tool "$tool" --models "$models" --out "$out" 2>/dev/null
  status=$?
  set -e
  [ "$status" = 2 ] || { echo "bench/scaling $bad: exit $status, expected 2" >&2; exit 1; }
done
"$python" - "$out/scaling.json" <<'CHECK'
import json, sys
result = json.load(open(sys.argv[1]))
rows = {(r["job"], r["threads"]) for r in result["rows"]}
assert rows == {(job, p) for job in ("aligner-cli", "batch-8", "plate") for p in (1, 2)}, rows
assert [(r["job"], r["threads"]) for r in result["band_starts"]] == [("aligner-cli", 1), ("aligner-cli", 2)]
assert all(0 <= fit["serial_fraction"] <= 1 for fit in result["amdahl"].values()), result["amdahl"]
assert len(result["runs"]) == 8 and all(r["wall_s"] > 0 for r in result["runs"])
copies = {r["job"]: r for r in result["copies_rows"]}
assert sorted(copies) == ["aligner-cli", "batch-8", "plate"], copies
assert all(r["copies"] == 2 and r["speedup"] > 0 and r["job_over_copies"] > 0
           for r in copies.values()), copies
assert all(len(r["walls_s"]) == 2 and 0 < r["walls_s"][0] <= r["makespan_s"] for r in result["copies"])
assert result["machine"]["cpu_model"] and result["tool"]["version"].startswith("toposlice")
print("bench_scaling_quick: scaling.json holds", len(result["runs"]), "runs")
CHECK
