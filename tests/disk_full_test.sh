#!/usr/bin/env bash
# CI test of a real full disk (docs/RELIABILITY.md, "What toposlice promises about your files"): a small
# tmpfs stands for the full disk. A job with several outputs, one of them on the full disk, must fail with
# one line that names that output and says "No space left on device", and leave none of its outputs and
# no temporary on either file system; a batch variant likewise. Every mask format and contour format is
# tried as the output that fills the disk.
#
# Usage: tests/disk_full_test.sh [BUILD_DIR]   (default: build; builds nothing)
# Needs root to mount the tmpfs; skips (exit 0) when it cannot mount one. Last line: "N passed, N failed".
set -uo pipefail

repo="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-build}"
[[ "$build" = /* ]] || build="$repo/$build"
bin="$build/tools/toposlice"
model="$repo/examples/example_part.stl"

work="$(mktemp -d)"
full="$work/full"
normal="$work/normal"
mkdir -p "$full" "$normal"
cleanup() {
  umount "$full" 2>/dev/null
  rm -rf "$work"
}
trap cleanup EXIT
# 64 KiB: more than a small file needs, less than any of the mask outputs below.
if ! mount -t tmpfs -o size=64k tmpfs "$full" 2>/dev/null; then
  echo "disk_full_test: skipped: cannot mount a tmpfs here (needs root)"
  echo "0 passed, 0 failed, 1 skipped"
  exit 0
fi

passed=0
failed=0
fail() {
  echo "FAIL: $*"
  failed=$((failed + 1))
}
pass() {
  echo "ok:   $*"
  passed=$((passed + 1))
}

# expect_clean NAME: the last run failed with one error line naming the full output and ENOSPC, and
# left nothing in either folder.
expect_clean() {
  local name="$1" status="$2" err="$3" target="$4"
  local lines left
  lines=$(wc -l <"$err")
  left=$(ls -A "$full" "$normal" | grep -v '^/' | grep -v '^$' | tr '\n' ' ')
  if [ "$status" -ne 1 ]; then
    fail "$name: exit $status, expected 1 ($(cat "$err"))"
  elif [ "$lines" -ne 1 ] || ! grep -q '^toposlice: error: ' "$err"; then
    fail "$name: expected one error line, got: $(cat "$err")"
  elif ! grep -q "$target" "$err"; then
    fail "$name: the error does not name $target: $(cat "$err")"
  elif ! grep -q 'No space left on device' "$err"; then
    fail "$name: the error does not say the disk is full: $(cat "$err")"
  elif grep -q '\.tmp-' "$err"; then
    fail "$name: the error names a temporary, not the output: $(cat "$err")"
  elif [ -n "$left" ]; then
    fail "$name: left behind: $left"
  else
    pass "$name"
  fi
}

for masks in x.sl1 x.exr xstack x.vdb x.goo x.nanodlp; do
  "$bin" slice "$model" -H 0.05 -o "$normal/r.cli" -o "$normal/r.3mf" --report "$normal/r.csv" \
    --summary "$normal/s.json" --masks "$full/$masks" --printer sl1 -q 2>"$work/err"
  expect_clean "slice with masks $masks on the full disk" $? "$work/err" "$full/$masks"
done

for contours in r.cli r.3mf r.svg; do
  svg=()
  [ "$contours" = r.svg ] && svg=(--svg-layers 0-last)
  "$bin" slice "$model" -H 0.05 -o "$full/$contours" "${svg[@]}" --masks "$normal/m.sl1" --printer sl1 \
    --report "$normal/r.csv" -q 2>"$work/err"
  expect_clean "slice with contours $contours on the full disk" $? "$work/err" "$full/$contours"
done

# A batch variant: its outputs go together or not at all; the summary names the failure.
cat >"$normal/job.json" <<EOF
{"template": {"model": "$model"}, "settings": {"layer_height": 0.05, "printer": "sl1"},
 "variants": [{"name": "a", "model": "$model", "contours": "$work/a.cli", "masks": "$full/a.sl1",
               "report": "$work/a.csv"}]}
EOF
"$bin" batch "$normal/job.json" -q >"$work/out" 2>"$work/err"
status=$?
rm "$normal/job.json"
if [ "$status" -ne 1 ]; then
  fail "batch: exit $status, expected 1"
elif ! grep -q 'No space left on device' "$work/err"; then
  fail "batch: the failure does not say the disk is full: $(cat "$work/err")"
elif [ -e "$work/a.cli" ] || [ -e "$work/a.csv" ] || [ -n "$(ls -A "$full")" ]; then
  fail "batch: a failed variant left outputs: $(ls "$work" "$full")"
else
  pass "batch variant with its masks on the full disk"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
