#!/usr/bin/env bash
# Builds the libFuzzer harnesses (fuzz/) with clang, AddressSanitizer and UBSan into ./build-fuzz, then runs
# each one for SECONDS_PER_TARGET seconds (default 60) from a fresh seed corpus in a temporary folder, and
# prints per target the executions run and the final corpus size. Exits non-zero when any target finds a
# crash, a leak, a timeout (> 10 s on one input) or an out-of-memory (> 2048 MB); the reproducer is kept.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET]
#
# Environment (all optional):
#   FUZZ_TARGETS     targets to run, default "stl template batch_job plate_job ply mesh gunzip profile"
#   FUZZ_CORPUS_DIR  keep the corpora in FUZZ_CORPUS_DIR/<target> (seeded when empty) so that the next run
#                    resumes from them; default: a temporary folder, removed after a clean run
#   FUZZ_KEEP=1      keep the temporary folder (corpora, logs) after a clean run too
#   FUZZ_BUILD_DIR   build folder, default build-fuzz
#   FUZZ_ARGS        more libFuzzer flags for every target, e.g. "-fork=2" or "-use_value_profile=1";
#                    "-fork=1 -ignore_crashes=1" keeps fuzzing past a known crash (the run still fails)
# Installs clang and libclang-rt-14-dev (libFuzzer) when missing; the normal build does not need them.
# See docs/RELIABILITY.md for the results so far and for longer runs.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)
seconds=${1:-60}
targets=${FUZZ_TARGETS:-stl template batch_job plate_job ply mesh gunzip profile}
build_dir=${FUZZ_BUILD_DIR:-build-fuzz}
models=${TOPOSLICE_MODELS_DIR:-$repo/../shared/models}
if ! [[ "$seconds" =~ ^[1-9][0-9]*$ ]]; then
  echo "usage: scripts/fuzz.sh [SECONDS_PER_TARGET]" >&2
  exit 2
fi

# --- Toolchain -------------------------------------------------------------------------------------------
missing=()
command -v clang++ >/dev/null 2>&1 || missing+=(clang)
dpkg-query -W -f='${Status}' libclang-rt-14-dev 2>/dev/null | grep -q 'install ok installed' ||
  missing+=(libclang-rt-14-dev)
if [ ${#missing[@]} -gt 0 ]; then
  echo "fuzz: installing ${missing[*]}"
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
probe_dir=$(mktemp -d)
printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' \
  >"$probe_dir/probe.cpp"
if ! clang++ -fsanitize=fuzzer,address,undefined "$probe_dir/probe.cpp" -o "$probe_dir/probe" 2>"$probe_dir/log"; then
  cat "$probe_dir/log" >&2
  echo "fuzz: clang++ cannot link a libFuzzer target (is libclang-rt-dev for $(clang++ --version | head -n1) installed?)" >&2
  rm -rf "$probe_dir"
  exit 1
fi
rm -rf "$probe_dir"

# --- Build -----------------------------------------------------------------------------------------------
# -O2 -g without NDEBUG: optimised enough to fuzz fast, with the code's debug asserts left on.
# -Wno-unknown-warning-option: the shared warning list has GCC-only flags (-Wno-restrict).
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g" -DCMAKE_CXX_FLAGS="-Wno-unknown-warning-option" \
  -DTOPOSLICE_BUILD_FUZZERS=ON -DTOPOSLICE_SANITIZE=address,undefined \
  -DTOPOSLICE_BUILD_TESTS=OFF -DTOPOSLICE_BUILD_BENCH=OFF >/dev/null
cmake --build "$build_dir" --parallel "$(nproc)" --target fuzz_stl fuzz_template fuzz_batch_job fuzz_plate_job fuzz_ply fuzz_mesh fuzz_gunzip fuzz_profile

# --- Corpora ---------------------------------------------------------------------------------------------
work=$(mktemp -d "${TMPDIR:-/tmp}/toposlice-fuzz.XXXXXX")
corpus_root=${FUZZ_CORPUS_DIR:-$work/corpus}
mkdir -p "$corpus_root"

# The first `count` facets of a binary STL, with the facet count patched: a small piece of a real scan.
binary_stl_head() {
  local src=$1 count=$2 dst=$3
  {
    head -c 80 "$src"
    printf "$(printf '\\x%02x\\x%02x\\x%02x\\x%02x' $((count & 255)) $((count >> 8 & 255)) \
      $((count >> 16 & 255)) $((count >> 24 & 255)))"
    head -c $((84 + 50 * count)) "$src" | tail -c +85
  } >"$dst"
}

seed_stl() {
  local dir=$1 edge=$models/stl_parser_edge_cases
  cp "$edge"/*.stl "$dir"/
  chmod u+w "$dir"/*
  gzip -c "$edge/tetrahedronMinusZero.bin.stl" >"$dir/gzip_binary_tetrahedron.stl.gz"
  gzip -c "$edge/tetrahedron.min.ascii.stl" >"$dir/gzip_ascii_tetrahedron.stl.gz"
  cat "$dir/gzip_ascii_tetrahedron.stl.gz" <(gzip -c "$edge/singleFace.ascii.stl") >"$dir/gzip_two_members.stl.gz"
  binary_stl_head "$models/knee_tibia_ssm_S001.stl" 300 "$dir/knee_tibia_first300.bin.stl"  # 15 KB
  head -n $((1 + 7 * 100)) "$models/gearwheel_ascii.stl" >"$dir/gearwheel_first100.ascii.stl"  # 26 KB, no endsolid
}

seed_target() {
  local target=$1 dir=$2
  case $target in
    stl) seed_stl "$dir" ;;
    template) cp fuzz/seeds/template/*.topo "$dir"/ ;;
    batch_job) cp fuzz/seeds/batch_job/*.json "$dir"/ ;;
    plate_job) cp fuzz/seeds/plate_job/*.json "$dir"/ ;;
    ply) cp fuzz/seeds/ply/* "$dir"/ ;;
    profile) cp fuzz/seeds/profile/*.json "$dir"/ ;;
    mesh)
      cp fuzz/seeds/mesh/* "$dir"/
      chmod u+w "$dir"/*
      head -c 16384 "$models/knee_tibia_ssm_S002.ply" >"$dir/knee_tibia_first16k.ply"  # truncated: an error path
      ;;
    gunzip)
      # Settings (fuzz/fuzz_gunzip.cpp) then a piece of a real binary STL: deflated by zlib at level 6
      # and at level 9 with small blocks, in parts of 64 and 272 bytes; and a gzip stream as it is.
      local piece=$work/piece.stl
      binary_stl_head "$models/knee_tibia_ssm_S001.stl" 200 "$piece"  # 10 KB
      { printf '\x01\x06\x68\x00\x00\x00\x00\x03'; cat "$piece"; } >"$dir/level6_parts64"
      { printf '\x01\x09\x60\x00\x00\x00\x00\x10'; cat "$piece"; } >"$dir/level9_small_blocks_parts272"
      { printf '\x00\x00\x00\x00\x00\x00\x00\x03'; gzip -c "$piece"; } >"$dir/gzip_stream_parts64"
      ;;
  esac
}

# --- Runs ------------------------------------------------------------------------------------------------
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:intercept_tls_get_addr=0}  # see scripts/sanitize.sh
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
failed=()
summary=()
for target in $targets; do
  case $target in
    stl) max_len=65536 dict=fuzz/seeds/stl.dict ;;
    template) max_len=65536 dict="" ;;
    batch_job) max_len=16384 dict=fuzz/seeds/batch_job.dict ;;
    plate_job) max_len=16384 dict=fuzz/seeds/plate_job.dict ;;
    ply) max_len=16384 dict=fuzz/seeds/ply.dict ;;
    mesh) max_len=16384 dict=fuzz/seeds/mesh.dict ;;
    gunzip) max_len=16384 dict="" ;;
    profile) max_len=8192 dict=fuzz/seeds/profile.dict ;;
    *) echo "fuzz: unknown target '$target' (stl, template, batch_job, plate_job, ply, mesh, gunzip, profile)" >&2; exit 2 ;;
  esac
  corpus=$corpus_root/$target
  mkdir -p "$corpus" "$work/artifacts/$target"
  [ -n "$(ls -A "$corpus")" ] || seed_target "$target" "$corpus"
  seeds=$(find "$corpus" -type f | wc -l)
  log=$work/$target.log
  echo "fuzz: $target for ${seconds}s from $seeds inputs (log $log)"
  rc=0
  "$build_dir/fuzz/fuzz_$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len="$max_len" \
    ${dict:+-dict="$dict"} -print_final_stats=1 -artifact_prefix="$work/artifacts/$target/" \
    ${FUZZ_ARGS:-} "$corpus" >"$log" 2>&1 || rc=$?

  # Executions: the final stats, or (fork mode prints none) the last status line "#N ...".
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)
  [ -n "$runs" ] || runs=$(grep -oE '^#[0-9]+' "$log" | tail -n1 | tr -d '#')
  status=$(grep -E '^#[0-9]+' "$log" | tail -n1 | grep -oE 'cov: [0-9]+ ft: [0-9]+ corp: [0-9]+(/[0-9]+[a-zA-Z]*)?' || true)
  files=$(find "$corpus" -type f | wc -l)
  line="$target: ${runs:-?} executions, corpus $files files (started from $seeds), ${status:-no status line}"
  artifacts=$(find "$work/artifacts/$target" -type f | wc -l)
  if [ "$rc" -ne 0 ] || [ "$artifacts" -gt 0 ]; then
    line="$line: FAILED (exit $rc, $artifacts reproducers)"
    failed+=("$target")
    echo "---- $target: last lines of $log" >&2
    tail -n 60 "$log" >&2
    echo "---- $target: distinct findings" >&2
    grep -hoE '[^ ]+: runtime error: .*|ERROR: [A-Za-z]+Sanitizer: [a-z-]+|invariant broken: .*|ERROR: libFuzzer: [a-z-]+' \
      "$log" | sort | uniq -c | sort -rn >&2 || true
    find "$work/artifacts/$target" -type f | sort | head -n 5 | while read -r artifact; do
      echo "---- reproducer $artifact (base64):" >&2
      base64 -w0 "$artifact" >&2
      echo >&2
    done
  fi
  summary+=("$line")
done

echo "fuzz: results (${seconds}s per target, $(nproc) cores, $(date -u +%Y-%m-%dT%H:%MZ))"
printf '  %s\n' "${summary[@]}"
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: FAILED: ${failed[*]}; logs, corpora and reproducers kept in $work" >&2
  echo "fuzz: replay one with $build_dir/fuzz/fuzz_<target> <reproducer>" >&2
  exit 1
fi
if [ "${FUZZ_KEEP:-0}" = 1 ]; then
  echo "fuzz: kept $work"
else
  rm -rf "$work"
fi
