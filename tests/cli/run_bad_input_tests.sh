#!/usr/bin/env bash
# The bad-input corpus (tests/bad_inputs/make_corpus.py): every case through the organfit
# command. Refusals: exit 2, one line on stderr naming the file (or scene key) and the
# problem, nothing left in the output folder, inputs unchanged. Tolerated defects: exit
# 0 with the expected warning. Prints "N passed, N failed".
set -u
src="$1"
bin="${ORGANFIT:?set ORGANFIT to the organfit binary}"
data="$src/../shared/data"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0
classes=()
if ! /usr/bin/python3 -c 'import pydicom' 2> /dev/null || [[ ! -d "$data/us-plus" ]]; then
  echo "skip: the corpus needs python3-pydicom and ../shared/data (scripts/setup.sh installs pydicom)"
  exit 0
fi
/usr/bin/python3 "$src/tests/bad_inputs/make_corpus.py" "$tmp/corpus" "$bin" "$data" > /dev/null || { echo "FAIL corpus generation"; exit 1; }
# The shared data as it was: each case must leave it so.
data_before=$(find "$data/us-plus" "$data/us-dicom" -type f -print0 | sort -z | xargs -0 md5sum | md5sum)
for dir in "$tmp"/corpus/*/; do
  name=$(basename "$dir")
  [[ "$name" == _* ]] && continue  # shared inputs of several cases
  dir=${dir%/}
  # The case's fields, read by one interpreter (its start-up was most of a case's time):
  # args, code, expect, secrets and class as shell-quoted assignments.
  eval "$(/usr/bin/python3 - "$dir" "$data" << 'PY'
import json, shlex, sys
case, data = sys.argv[1], sys.argv[2]
c = json.load(open(case + "/case.json"))
quote = lambda values: " ".join(shlex.quote(v) for v in values)
print("args=(" + quote(a.replace("{case}", case).replace("{data}", data) for a in c["args"]) + ")")
print("code=" + shlex.quote(str(c["code"])))
print("expect=" + shlex.quote(c["expect"]))
print("secrets=(" + quote(c.get("secrets", [])) + ")")
print("class=" + shlex.quote(c.get("class", "other")))
PY
)"
  before=$(cd "$dir" && find . -path ./out -prune -o -type f -print0 | sort -z | xargs -0 md5sum | md5sum)
  out_before=$(cd "$dir" && [[ -d out ]] && find out -print0 | sort -z | xargs -0 md5sum 2>&1 | md5sum)
  timeout 120 "$bin" "${args[@]}" > "$tmp/out.txt" 2> "$tmp/err.txt"
  got=$?
  after=$(cd "$dir" && find . -path ./out -prune -o -type f -print0 | sort -z | xargs -0 md5sum | md5sum)
  data_after=$(find "$data/us-plus" "$data/us-dicom" -type f -print0 | sort -z | xargs -0 md5sum | md5sum)
  lines=$(grep -c . "$tmp/err.txt")
  why=""
  # No patient name or ID in any output line, and every line bounded.
  for secret in "${secrets[@]}"; do
    [[ -n "$secret" ]] && grep -qF -- "$secret" "$tmp/out.txt" "$tmp/err.txt" && why="prints the patient's '$secret'"
  done
  longest=$(awk '{ if (length($0) > m) m = length($0) } END { print m + 0 }' "$tmp/err.txt")
  [[ -z "$why" && $longest -gt 600 ]] && why="a stderr line of $longest characters"
  [[ -z "$why" && $got -ne $code ]] && why="exit $got, expected $code"
  [[ -z "$why" && -n "$expect" ]] && ! grep -qF -- "$expect" "$tmp/err.txt" && why="stderr lacks '$expect'"
  if [[ -z "$why" && $code -eq 2 ]]; then
    [[ $lines -ne 1 ]] && why="$lines lines on stderr"
    [[ -z "$why" ]] && ! grep -qE "(/|\.yaml:[0-9]+: [a-z_]+\.|--[a-z]+|segment: )" "$tmp/err.txt" && why="names no file, key or option"
    out_after=$(cd "$dir" && [[ -d out ]] && find out -print0 | sort -z | xargs -0 md5sum 2>&1 | md5sum)
    [[ -z "$why" && "$out_before" != "$out_after" ]] && why="--out not left as it was: $(ls -A "$dir/out" 2> /dev/null)"
  fi
  [[ -z "$why" && "$before" != "$after" ]] && why="an input file changed"
  [[ -z "$why" && "$data_before" != "$data_after" ]] && why="a shared data file changed"
  if [[ -z "$why" ]]; then
    echo "ok   bad_input.$name"
    passed=$((passed + 1))
    classes+=("$class")
  else
    echo "FAIL bad_input.$name: $why: $(head -c 300 "$tmp/err.txt")"
    failed=$((failed + 1))
  fi
done
# Inputs that crashed or exhausted memory under the fuzzers: now read (exit 0) or refused
# in one line (exit 2), never a crash, and within 300 MB (GDCM allocated 1.8 to 2.8 GB by
# a corrupt length before the checks; a refusal peaks near 50 MB).
"$bin" --quiet synth pelvis --out "$tmp/tiny" --columns 40 --rows 40 --pixel-mm 10 --slices 8 --slice-mm 10 > /dev/null
for f in "$src"/tests/fuzz/regressions/*.dcm; do
  timeout 60 /usr/bin/time -o "$tmp/peak_kb" -f %M "$bin" segment --ct "$tmp/tiny/ct" --rtstruct "$f" --roi Prostate --out "$tmp/x.nrrd" > /dev/null 2> "$tmp/err.txt"
  code=$?
  peak_kb=$(tail -1 "$tmp/peak_kb")
  if [[ ( $code -eq 0 || ( $code -eq 2 && $(grep -c . "$tmp/err.txt") -eq 1 ) ) && $peak_kb -lt 300000 ]]; then echo "ok   fuzz_regression.$(basename "$f")"; passed=$((passed + 1));
  else echo "FAIL fuzz_regression.$(basename "$f"): exit $code, peak $peak_kb kB"; failed=$((failed + 1)); fi
done
for f in "$src"/tests/fuzz/regressions/*.mha; do
  timeout 60 "$bin" us-points --us "$f" --out "$tmp/x.csv" > /dev/null 2> "$tmp/err.txt"
  code=$?
  if [[ $code -eq 2 && $(grep -c . "$tmp/err.txt") -eq 1 ]]; then echo "ok   fuzz_regression.$(basename "$f")"; passed=$((passed + 1));
  else echo "FAIL fuzz_regression.$(basename "$f"): exit $code"; failed=$((failed + 1)); fi
done
for f in "$src"/tests/fuzz/regressions/*.yaml; do
  for cmd in validate run; do
    rm -rf "$tmp/yout"
    if [[ $cmd == run ]]; then args=(--out "$tmp/yout"); else args=(); fi
    timeout 60 "$bin" $cmd "$f" "${args[@]}" > /dev/null 2> "$tmp/err.txt"
    code=$?
    if [[ $code -eq 2 && $(grep -c . "$tmp/err.txt") -eq 1 && ! -e "$tmp/yout" ]]; then echo "ok   fuzz_regression.$cmd.$(basename "$f")"; passed=$((passed + 1));
    else echo "FAIL fuzz_regression.$cmd.$(basename "$f"): exit $code"; failed=$((failed + 1)); fi
  done
done
printf '%s\n' "${classes[@]}" | sort | uniq -c | sed 's/^/cases by class: /'
echo "$passed passed, $failed failed"
[[ $failed -eq 0 && $passed -ge 100 ]]
